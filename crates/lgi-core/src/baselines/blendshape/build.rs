//! Building a [`BlendshapeSolver`]: the input checks, the choice between the dense normal
//! equations (AᵀA + l2 I and its Cholesky factor) and their low-rank form, and the Gram
//! matrices both are made from.

use super::low_rank::LowRank;
use super::BlendshapeSolver;
use crate::error::{LgiError, Result};
use crate::linalg::cholesky;
use crate::simd::with_avx2;

impl BlendshapeSolver {
    /// `a` is row-major `rows × shapes`; `l2` and `penalty` are absolute, non-negative.
    pub fn new(a: Vec<f64>, rows: usize, shapes: usize, l2: f64, penalty: f64) -> Result<Self> {
        if a.len() != rows * shapes || shapes == 0 {
            return Err(LgiError::Input(format!(
                "blendshape matrix of {} values is not {rows}×{shapes} with shapes > 0",
                a.len()
            )));
        }
        if !(l2.is_finite() && l2 >= 0.0 && penalty.is_finite() && penalty >= 0.0) {
            return Err(LgiError::Input(format!(
                "l2 ({l2}) and penalty ({penalty}) must be finite and non-negative"
            )));
        }
        if a.iter().any(|x| !x.is_finite()) {
            return Err(LgiError::Input(
                "blendshape matrix has non-finite entries".into(),
            ));
        }
        let mut me = BlendshapeSolver {
            a,
            rows,
            shapes,
            l2,
            penalty,
            full_gram: Vec::new(),
            full: Vec::new(),
            low_rank: None,
        };
        me.low_rank = LowRank::new(
            &me.a,
            rows,
            shapes,
            &me.plain_gram_diagonal(),
            |p| me.plain_gram_column(p),
            l2,
        )?;
        // The whole Gram matrix and its factor serve only the dense path (S² doubles, 32 MB,
        // and S³/3 flops at 2,000 shapes; the local fits keep one solver per bundle).
        if me.low_rank.is_none() {
            let gram = me.gram(&vec![true; rows]);
            me.keep_dense(gram)?;
        }
        Ok(me)
    }

    /// The diagonal of AᵀA (all rows), each entry the bits `gram`'s diagonal less the ridge
    /// had: (Σ + l2) − l2.
    pub(super) fn plain_gram_diagonal(&self) -> Vec<f64> {
        let s = self.shapes;
        let mut d = vec![0.0; s];
        for row in self.a.chunks_exact(s) {
            for (x, a) in d.iter_mut().zip(row) {
                *x += a * a;
            }
        }
        d.iter().map(|x| (x + self.l2) - self.l2).collect()
    }

    /// Column p of AᵀA (all rows), each entry the bits of `gram`'s (the rows summed in the
    /// same order; a product commutes exactly), its diagonal entry as
    /// [`plain_gram_diagonal`](Self::plain_gram_diagonal)'s.
    pub(super) fn plain_gram_column(&self, p: usize) -> Vec<f64> {
        let s = self.shapes;
        let mut c = vec![0.0; s];
        for row in self.a.chunks_exact(s) {
            let ap = row[p];
            for (x, a) in c.iter_mut().zip(row) {
                *x += a * ap;
            }
        }
        let mut own = 0.0;
        for row in self.a.chunks_exact(s) {
            own += row[p] * row[p];
        }
        c[p] = (own + self.l2) - self.l2;
        c
    }

    /// Keeps `gram` (AᵀA + l2 I over all rows) and its Cholesky factor for the dense path.
    fn keep_dense(&mut self, gram: Vec<f64>) -> Result<()> {
        self.full = cholesky(self.shapes, gram.clone())?;
        self.full_gram = gram;
        Ok(())
    }

    /// Number of shapes S.
    pub fn num_shapes(&self) -> usize {
        self.shapes
    }

    /// Number of rows R.
    pub fn num_rows(&self) -> usize {
        self.rows
    }

    /// What every fit of complete frames would make on first use, made now (the low-rank
    /// form's whitened rows): a model's build or load does it, not a take's first solve.
    pub fn derive(&self) -> Result<()> {
        match &self.low_rank {
            Some(lr) => lr.whiten(1.0 / (self.l2 + self.penalty)),
            None => Ok(()),
        }
    }

    /// The rank of the normal equations' low-rank form, when the solver uses it (a matrix of
    /// rank at most half its shapes, e.g. an augmented dataset's).
    pub fn low_rank(&self) -> Option<usize> {
        self.low_rank.as_ref().map(LowRank::rank)
    }

    /// AᵀA + l2 I (S × S) over the rows marked `present`.
    pub(super) fn gram(&self, present: &[bool]) -> Vec<f64> {
        let s = self.shapes;
        let mut g = vec![0.0; s * s];
        for (r, _) in present.iter().enumerate().filter(|(_, &p)| p) {
            add_outer_lower(&mut g, &self.a[r * s..(r + 1) * s]);
        }
        for i in 0..s {
            g[i * s + i] += self.l2;
            for j in 0..i {
                g[j * s + i] = g[i * s + j];
            }
        }
        g
    }

    /// The same solver on the dense path (its Gram matrix and factor made, the low-rank form
    /// dropped): the reference the tests compare the low-rank path with, and where a fit the
    /// low-rank path does not finish is solved again ([`crate::LocalFits`]).
    pub(crate) fn dense_only(&self) -> Result<Self> {
        let mut dense = self.clone();
        dense.low_rank = None;
        dense.keep_dense(dense.gram(&vec![true; dense.rows]))?;
        Ok(dense)
    }
}

with_avx2! {
/// `g += row rowᵀ` on and below the diagonal (`g` S × S row-major, `row` S long): each entry
/// adds its product as the Gram's rows come, the same bits on either build.
fn add_outer_lower(g: &mut [f64], row: &[f64]) {
    let s = row.len();
    for (i, &ri) in row.iter().enumerate() {
        for (gij, &rj) in g[i * s..i * s + i + 1].iter_mut().zip(&row[..=i]) {
            *gij += ri * rj;
        }
    }
}
}
