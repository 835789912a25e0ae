//! Sparse row-major (CSR) weights over sites: the V×B sewing matrix W, the Sibson rows it is
//! built from and the plans for missing markers. One general type so those stages share it;
//! `sanity_check` states its invariants for tests and fuzzers.

/// Sparse row-major weights: row `r` has entries `cols[row_start[r]..row_start[r + 1]]` with
/// `vals` at the same positions (f64, > 0, summing to 1 in every non-empty row, columns sorted).
#[derive(Debug, Clone, PartialEq)]
pub struct SparseWeights {
    /// Start of each row in `cols`/`vals`, plus one final entry (num_rows + 1 entries).
    pub row_start: Vec<u32>,
    /// Column (site) index of each entry.
    pub cols: Vec<u32>,
    /// Weight of each entry.
    pub vals: Vec<f64>,
    /// Number of columns (sites).
    pub num_cols: usize,
}

impl SparseWeights {
    /// No rows, `num_cols` columns.
    pub fn empty(num_cols: usize) -> SparseWeights {
        SparseWeights {
            row_start: vec![0],
            cols: Vec::new(),
            vals: Vec::new(),
            num_cols,
        }
    }

    /// Appends a row.
    pub fn push_row(&mut self, cols: &[u32], vals: &[f64]) {
        self.cols.extend_from_slice(cols);
        self.vals.extend_from_slice(vals);
        self.row_start.push(self.cols.len() as u32);
    }

    /// Number of rows (query points).
    pub fn num_rows(&self) -> usize {
        self.row_start.len().saturating_sub(1)
    }

    /// Columns and weights of row `r`.
    ///
    /// # Panics
    /// If `r >= self.num_rows()`, like slice indexing.
    pub fn row(&self, r: usize) -> (&[u32], &[f64]) {
        let (a, b) = (self.row_start[r] as usize, self.row_start[r + 1] as usize);
        (&self.cols[a..b], &self.vals[a..b])
    }

    /// Checks the CSR invariants and panics naming the first one broken: `row_start` starts at
    /// 0, never decreases and ends at `cols.len() == vals.len()`; in each row the columns are
    /// strictly increasing and below `num_cols`, the weights finite and positive, and a
    /// non-empty row sums to 1 (within 1e-9). For tests and fuzzers, like spade's
    /// `sanity_check`: the solver trusts these invariants without checking them.
    ///
    /// # Panics
    /// When an invariant does not hold.
    pub fn sanity_check(&self) {
        assert!(
            self.row_start.first() == Some(&0),
            "row_start must start at 0: {:?}",
            self.row_start.first()
        );
        assert!(
            self.row_start.windows(2).all(|w| w[0] <= w[1]),
            "row_start decreases"
        );
        let nnz = self.row_start.last().map_or(0, |&n| n as usize);
        assert!(
            nnz == self.cols.len() && nnz == self.vals.len(),
            "row_start ends at {nnz} for {} columns and {} weights",
            self.cols.len(),
            self.vals.len()
        );
        for r in 0..self.num_rows() {
            let (cols, vals) = self.row(r);
            assert!(
                cols.windows(2).all(|c| c[0] < c[1]),
                "row {r}: columns not strictly increasing {cols:?}"
            );
            assert!(
                cols.iter().all(|&c| (c as usize) < self.num_cols),
                "row {r}: a column is not below {} {cols:?}",
                self.num_cols
            );
            assert!(
                vals.iter().all(|&v| v.is_finite() && v > 0.0),
                "row {r}: a weight is not finite and positive {vals:?}"
            );
            let sum: f64 = vals.iter().sum();
            assert!(
                cols.is_empty() || (sum - 1.0).abs() <= 1e-9,
                "row {r}: weights sum to {sum}"
            );
        }
    }
}

/// A matrix's rows with some of them replaced: the plan of a missing set shares the full
/// plan's rows and keeps only those that the missing bundles change.
#[derive(Debug, Clone)]
pub struct PatchedWeights {
    base: std::sync::Arc<SparseWeights>,
    /// The replacing rows.
    patch: SparseWeights,
    /// Per row of `base`: its row in `patch`, or `u32::MAX` (empty: none replaced).
    patched: Vec<u32>,
}

impl PatchedWeights {
    /// `base`'s rows, none replaced.
    pub fn whole(base: std::sync::Arc<SparseWeights>) -> PatchedWeights {
        PatchedWeights {
            base,
            patch: SparseWeights::empty(0),
            patched: Vec::new(),
        }
    }

    /// `base` with the rows `rows` (row, its columns and weights; each row once) replaced.
    pub fn new<'a>(
        base: std::sync::Arc<SparseWeights>,
        rows: impl IntoIterator<Item = (u32, (&'a [u32], &'a [f64]))>,
    ) -> PatchedWeights {
        let rows: Vec<_> = rows.into_iter().collect();
        let nnz = rows.iter().map(|(_, (c, _))| c.len()).sum();
        let mut patched = vec![u32::MAX; base.num_rows()];
        let mut patch = SparseWeights {
            row_start: Vec::with_capacity(rows.len() + 1),
            cols: Vec::with_capacity(nnz),
            vals: Vec::with_capacity(nnz),
            num_cols: base.num_cols,
        };
        patch.row_start.push(0);
        for (r, (cols, vals)) in rows {
            patched[r as usize] = patch.num_rows() as u32;
            patch.push_row(cols, vals);
        }
        PatchedWeights {
            base,
            patch,
            patched,
        }
    }

    /// The rows before replacement.
    pub fn base(&self) -> &SparseWeights {
        &self.base
    }

    /// The rows before replacement, shared.
    pub fn shared_base(&self) -> std::sync::Arc<SparseWeights> {
        self.base.clone()
    }

    /// Columns and weights of row `r` (panics out of range, like slice indexing).
    pub fn row(&self, r: usize) -> (&[u32], &[f64]) {
        self.view().row(r)
    }

    /// A borrowed view for reading rows.
    pub fn view(&self) -> WeightRows<'_> {
        WeightRows {
            base: &self.base,
            patch: (!self.patched.is_empty()).then_some((&self.patch, &self.patched[..])),
        }
    }

    /// The rows as one matrix (tests).
    pub fn to_sparse(&self) -> SparseWeights {
        let view = self.view();
        let mut out = SparseWeights::empty(self.base.num_cols);
        for r in 0..self.base.num_rows() {
            let (cols, vals) = view.row(r);
            out.push_row(cols, vals);
        }
        out
    }
}

/// Rows of a [`SparseWeights`] or a [`PatchedWeights`], read the same way.
#[derive(Debug, Clone, Copy)]
pub struct WeightRows<'a> {
    base: &'a SparseWeights,
    patch: Option<(&'a SparseWeights, &'a [u32])>,
}

impl<'a> WeightRows<'a> {
    /// Columns and weights of row `r` (panics out of range, like slice indexing).
    #[inline]
    pub fn row(&self, r: usize) -> (&'a [u32], &'a [f64]) {
        if let Some((patch, patched)) = self.patch {
            let p = patched[r];
            if p != u32::MAX {
                return patch.row(p as usize);
            }
        }
        self.base.row(r)
    }
}

impl<'a> From<&'a PatchedWeights> for WeightRows<'a> {
    fn from(w: &'a PatchedWeights) -> Self {
        w.view()
    }
}

impl<'a> From<&'a SparseWeights> for WeightRows<'a> {
    fn from(base: &'a SparseWeights) -> Self {
        WeightRows { base, patch: None }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two_rows() -> SparseWeights {
        SparseWeights {
            row_start: vec![0, 2, 2, 3],
            cols: vec![0, 2, 1],
            vals: vec![0.25, 0.75, 1.0],
            num_cols: 3,
        }
    }

    #[test]
    fn rows_are_the_csr_slices_and_empty_rows_are_allowed() {
        let w = two_rows();
        w.sanity_check();
        assert_eq!(w.num_rows(), 3);
        assert_eq!(w.row(0), (&[0, 2][..], &[0.25, 0.75][..]));
        assert_eq!(w.row(1), (&[][..], &[][..]));
        assert_eq!(w.row(2), (&[1][..], &[1.0][..]));
    }

    #[test]
    #[should_panic(expected = "row 0: columns not strictly increasing")]
    fn sanity_check_rejects_unsorted_columns() {
        let mut w = two_rows();
        w.cols.swap(0, 1);
        w.sanity_check();
    }

    #[test]
    #[should_panic(expected = "row 2: weights sum to 0.5")]
    fn sanity_check_rejects_rows_not_summing_to_one() {
        let mut w = two_rows();
        w.vals[2] = 0.5;
        w.sanity_check();
    }

    #[test]
    #[should_panic(expected = "a column is not below 3")]
    fn sanity_check_rejects_columns_out_of_range() {
        let mut w = two_rows();
        w.cols[2] = 3;
        w.sanity_check();
    }
}
