//! The Cholesky factors of a dense fit's pieces, kept across the fits of one window: a
//! window's frames in a row mostly have the same rows present and the same weights out of the
//! box, so the next frame's pieces are the last frame's. A factor is a function of the piece
//! alone (its rows present, its clamped weights), so one kept is the bits one made again.

use crate::error::Result;
use crate::linalg::cholesky_from;

/// Pieces kept at most: the last few a window's frames went through.
const KEPT: usize = 4;

/// One piece's factor: the Hessian AᵀA + l2 I over `present` rows, plus the penalty on the
/// diagonal of the `clamped` weights.
#[derive(Debug, Clone)]
struct Piece {
    present: Vec<bool>,
    clamped: Vec<bool>,
    factor: Vec<f64>,
}

/// The factors of the pieces a fit (or a window's fits in turn) went through, the most
/// recently used first. Empty: every piece factorised anew.
#[derive(Debug, Clone, Default)]
pub(crate) struct PieceFactors {
    pieces: Vec<Piece>,
}

impl PieceFactors {
    /// The lower Cholesky factor (`n × n` row-major) of the piece with `present` rows and
    /// `clamped` weights. `hessian` makes that piece's matrix when no factor of it is kept;
    /// then the kept factor with the same rows that agrees with `clamped` longest lends its
    /// leading columns ([`cholesky_from`]: the same bits as a whole factorisation).
    pub(crate) fn factor(
        &mut self,
        n: usize,
        present: &[bool],
        clamped: &[bool],
        hessian: impl FnOnce() -> Result<Vec<f64>>,
    ) -> Result<&[f64]> {
        if let Some(at) = self
            .pieces
            .iter()
            .position(|p| p.clamped == clamped && p.present == present)
        {
            let hit = self.pieces.remove(at);
            self.pieces.insert(0, hit);
            return Ok(&self.pieces[0].factor);
        }
        let mut h = hessian()?;
        let agreeing = |p: &Piece| {
            p.clamped
                .iter()
                .zip(clamped)
                .take_while(|(a, b)| a == b)
                .count()
        };
        let lender = self
            .pieces
            .iter()
            .filter(|p| p.present == present)
            .max_by_key(|p| agreeing(p));
        let start = lender.map_or(0, agreeing);
        if let Some(from) = lender.filter(|_| start > 0) {
            for (row, kept) in h.chunks_exact_mut(n).zip(from.factor.chunks_exact(n)) {
                let lead = start.min(row.len());
                row[..lead].copy_from_slice(&kept[..lead]);
            }
        }
        let factor = cholesky_from(n, h, start)?;
        self.pieces.insert(
            0,
            Piece {
                present: present.to_vec(),
                clamped: clamped.to_vec(),
                factor,
            },
        );
        self.pieces.truncate(KEPT);
        Ok(&self.pieces[0].factor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::cholesky;
    use crate::test_values::values;

    /// A symmetric positive definite `n × n` matrix: M Mᵀ + 0.1 I.
    fn matrix(n: usize, seed: u64) -> Vec<f64> {
        let m = values(n * n, seed);
        let mut g = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                g[i * n + j] = (0..n).map(|k| m[i * n + k] * m[j * n + k]).sum::<f64>();
            }
            g[i * n + i] += 0.1;
        }
        g
    }

    fn with_penalty(g: &[f64], n: usize, clamped: &[bool]) -> Vec<f64> {
        let mut h = g.to_vec();
        for (i, &c) in clamped.iter().enumerate() {
            if c {
                h[i * n + i] += 7.0;
            }
        }
        h
    }

    #[test]
    fn kept_and_lent_factors_are_the_bits_of_a_whole_factorisation() {
        let n = 19;
        let g = matrix(n, 3);
        let present = vec![true; 4];
        let mut kept = PieceFactors::default();
        let sets: Vec<Vec<bool>> = [
            vec![],
            vec![12],
            vec![12, 15],
            vec![3, 12],
            vec![12],
            vec![0, 18],
            vec![12, 15],
            vec![18],
        ]
        .iter()
        .map(|on| (0..n).map(|i| on.contains(&i)).collect())
        .collect();
        let mut made = 0;
        for clamped in &sets {
            let want = cholesky(n, with_penalty(&g, n, clamped)).unwrap();
            let got = kept
                .factor(n, &present, clamped, || {
                    made += 1;
                    Ok(with_penalty(&g, n, clamped))
                })
                .unwrap()
                .to_vec();
            let lower = |a: &[f64]| {
                (0..n)
                    .flat_map(|i| (0..=i).map(move |j| a[i * n + j].to_bits()))
                    .collect::<Vec<_>>()
            };
            assert_eq!(lower(&got), lower(&want), "clamped {clamped:?}");
        }
        // {12} and {12, 15} were kept when asked again; the rest were made.
        assert_eq!(made, sets.len() - 2);
    }

    #[test]
    fn another_set_of_rows_never_lends_its_columns() {
        let n = 9;
        let (g1, g2) = (matrix(n, 5), matrix(n, 6));
        let clamped = vec![false; n];
        let mut kept = PieceFactors::default();
        kept.factor(n, &[true, false], &clamped, || Ok(g1.clone()))
            .unwrap();
        let got = kept
            .factor(n, &[true, true], &clamped, || Ok(g2.clone()))
            .unwrap()
            .to_vec();
        assert_eq!(got, cholesky(n, g2).unwrap());
    }
}
