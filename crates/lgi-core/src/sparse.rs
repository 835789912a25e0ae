//! Sparse row-major (CSR) weights over sites: the V×B sewing matrix W, the Sibson rows it is
//! built from and the plans for missing markers. One general type so those stages share it;
//! `sanity_check` states its invariants for tests and fuzzers.

use std::sync::Arc;

/// One row's columns and weights.
pub type Row<'a> = (&'a [u32], &'a [f64]);

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

    /// These weights by column within blocks of `block` consecutive rows ([`BlockColumns`]).
    pub fn block_columns(&self, block: usize) -> BlockColumns {
        WeightRows::from(self).block_columns(block)
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

/// Another matrix's rows with some replaced, the others read from it in place: a missing
/// marker set's sewing weights are the full plan's but for the rows near the missing markers,
/// and copying the ~1 MB full plan around its replaced rows (~20,000 runs on ICT) cost more
/// than the rest of such a plan's assembly.
#[derive(Debug)]
pub struct PatchedWeights {
    base: Arc<SparseWeights>,
    /// Per row: its index in `rows`, or `u32::MAX` for the base's row.
    slot: Vec<u32>,
    rows: SparseWeights,
}

/// Empty buffers of a [`PatchedWeights`] no longer used, for the next one to fill.
#[derive(Debug, Default)]
pub struct PatchBuffers {
    slot: Vec<u32>,
    rows: Option<SparseWeights>,
}

impl PatchedWeights {
    /// `base`'s rows with row r replaced by `rows.row(i)` wherever `replaced` gives `(r, i)`
    /// (a later pair for the same r wins), written into `buffers` (from [`into_buffers`](Self::into_buffers)
    /// of a patch no longer used, or the default). `fill(&mut rows)` appends the new rows to
    /// the (emptied) row buffer first; pairs naming a row of `base` or of `rows` that does not
    /// exist are ignored.
    pub fn new(
        base: Arc<SparseWeights>,
        buffers: PatchBuffers,
        fill: impl FnOnce(&mut SparseWeights),
        replaced: impl IntoIterator<Item = (usize, u32)>,
    ) -> PatchedWeights {
        let PatchBuffers { mut slot, rows } = buffers;
        let mut rows = rows.unwrap_or_else(|| SparseWeights::empty(base.num_cols));
        rows.row_start.clear();
        rows.row_start.push(0);
        rows.cols.clear();
        rows.vals.clear();
        rows.num_cols = base.num_cols;
        fill(&mut rows);
        slot.clear();
        slot.resize(base.num_rows(), u32::MAX);
        let num_new = rows.num_rows();
        for (r, i) in replaced {
            if let Some(s) = slot.get_mut(r).filter(|_| (i as usize) < num_new) {
                *s = i;
            }
        }
        PatchedWeights { base, slot, rows }
    }

    /// The matrix whose rows are read where none was replaced.
    pub fn base(&self) -> &Arc<SparseWeights> {
        &self.base
    }

    /// Its buffers, for a later [`new`](Self::new) to clear and fill.
    pub fn into_buffers(self) -> PatchBuffers {
        PatchBuffers {
            slot: self.slot,
            rows: Some(self.rows),
        }
    }

    /// Columns and weights of row `r`.
    ///
    /// # Panics
    /// If `r` is not a row, like slice indexing.
    #[inline]
    pub fn row(&self, r: usize) -> Row<'_> {
        match self.slot[r] {
            u32::MAX => self.base.row(r),
            i => self.rows.row(i as usize),
        }
    }
}

/// The rows of a weight matrix, whole or patched: what the sewing reads.
#[derive(Debug, Clone, Copy)]
pub enum WeightRows<'a> {
    /// A matrix of its own.
    Whole(&'a SparseWeights),
    /// Another's with some rows replaced.
    Patched(&'a PatchedWeights),
}

impl<'a> From<&'a SparseWeights> for WeightRows<'a> {
    fn from(w: &'a SparseWeights) -> Self {
        WeightRows::Whole(w)
    }
}

impl<'a> WeightRows<'a> {
    /// Columns and weights of row `r`.
    ///
    /// # Panics
    /// If `r >= self.num_rows()`, like slice indexing.
    #[inline]
    pub fn row(self, r: usize) -> Row<'a> {
        match self {
            WeightRows::Whole(w) => w.row(r),
            WeightRows::Patched(p) => p.row(r),
        }
    }

    /// Number of rows.
    pub fn num_rows(self) -> usize {
        match self {
            WeightRows::Whole(w) => w.num_rows(),
            WeightRows::Patched(p) => p.slot.len(),
        }
    }

    /// Number of columns (sites).
    pub fn num_cols(self) -> usize {
        match self {
            WeightRows::Whole(w) => w.num_cols,
            WeightRows::Patched(p) => p.base.num_cols,
        }
    }

    /// Number of entries (weights) over all rows.
    pub fn num_entries(self) -> usize {
        match self {
            WeightRows::Whole(w) => w.cols.len(),
            WeightRows::Patched(_) => (0..self.num_rows()).map(|r| self.row(r).0.len()).sum(),
        }
    }

    /// The same rows as one matrix of their own.
    pub fn to_sparse(self) -> SparseWeights {
        if let WeightRows::Whole(w) = self {
            return w.clone();
        }
        let mut out = SparseWeights::empty(self.num_cols());
        for r in 0..self.num_rows() {
            let (cols, vals) = self.row(r);
            out.push_row(cols, vals);
        }
        out
    }

    /// These weights by column within blocks of `block` consecutive rows ([`BlockColumns`]).
    pub fn block_columns(self, block: usize) -> BlockColumns {
        let mut out = BlockColumns::new(block);
        let entries = self.num_entries();
        out.rows.reserve(entries);
        out.vals.reserve(entries);
        let n = self.num_rows();
        let mut count = Vec::new();
        for first in (0..n).step_by(out.block) {
            out.push_block(self, first, (first + out.block).min(n), &mut count);
        }
        out
    }
}

/// Sparse weights by column within blocks of consecutive rows: block `c` covers rows
/// `c * block..` and lists its columns ascending, each with its entries' rows (offsets in the
/// block, ascending) and weights. Reading a row's entries column by column in this order
/// visits, for every row, its entries in the row's own (ascending column) order.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockColumns {
    /// Rows per block.
    pub block: usize,
    block_start: Vec<u32>,
    col: Vec<u32>,
    col_end: Vec<u32>,
    rows: Vec<u16>,
    vals: Vec<f64>,
}

impl BlockColumns {
    /// No blocks yet; blocks of `block` rows (at most 65,536: offsets are 16-bit).
    fn new(block: usize) -> BlockColumns {
        BlockColumns {
            block: block.clamp(1, usize::from(u16::MAX) + 1),
            block_start: vec![0],
            col: Vec::new(),
            col_end: Vec::new(),
            rows: Vec::new(),
            vals: Vec::new(),
        }
    }

    /// Appends rows `first..last` of `w` (at most `block` of them) as the next block: a
    /// counting sort of their entries by column (`count`: scratch), rows staying ascending.
    fn push_block(&mut self, w: WeightRows<'_>, first: usize, last: usize, count: &mut Vec<u32>) {
        let last = last.min(first + self.block);
        count.clear();
        count.resize(w.num_cols(), 0);
        let mut entries = 0;
        for r in first..last {
            let cols = w.row(r).0;
            entries += cols.len();
            for &c in cols {
                count[c as usize] += 1;
            }
        }
        // `count` becomes each column's next slot.
        let base = self.rows.len();
        let mut end = base as u32;
        for (c, k) in count.iter_mut().enumerate() {
            if *k > 0 {
                let start = end;
                end += *k;
                self.col.push(c as u32);
                self.col_end.push(end);
                *k = start;
            }
        }
        self.rows.resize(base + entries, 0);
        self.vals.resize(base + entries, 0.0);
        for r in first..last {
            let (cols, vals) = w.row(r);
            for (&c, &v) in cols.iter().zip(vals) {
                let slot = &mut count[c as usize];
                self.rows[*slot as usize] = (r - first) as u16;
                self.vals[*slot as usize] = v;
                *slot += 1;
            }
        }
        self.block_start.push(self.col.len() as u32);
    }

    /// True when `base..base + len` are the rows of block `c` (its whole rows, or the first
    /// `len` of a partial last block).
    pub fn covers(&self, c: usize, base: usize, len: usize) -> bool {
        base == c * self.block && len <= self.block && c + 1 < self.block_start.len()
    }

    /// Block `c`'s columns in ascending order, each with its (row offset, weight) entries.
    pub fn columns(&self, c: usize) -> impl Iterator<Item = (u32, &[u16], &[f64])> + '_ {
        let (s, e) = (
            self.block_start.get(c).copied().unwrap_or(0) as usize,
            self.block_start.get(c + 1).copied().unwrap_or(0) as usize,
        );
        (s..e).map(move |j| {
            let from = if j == 0 {
                0
            } else {
                self.col_end[j - 1] as usize
            };
            let to = self.col_end[j] as usize;
            (self.col[j], &self.rows[from..to], &self.vals[from..to])
        })
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

    proptest::proptest! {
        /// Replacing any subset of rows (first, last, neighbours, empty rows; several rows by
        /// one new row) reads as the matrix rebuilt row by row with those rows swapped in,
        /// whole and by block columns, also when written into a used patch's buffers.
        #[test]
        fn patched_rows_equal_the_matrix_rebuilt_row_by_row(
            lens in proptest::collection::vec(0usize..4, 1..12),
            pick in proptest::collection::vec(0usize..3, 12),
            block in 1usize..5,
        ) {
            let mut w = SparseWeights::empty(4);
            for (r, &n) in lens.iter().enumerate() {
                let cols: Vec<u32> = (0..n as u32).collect();
                let vals: Vec<f64> = (0..n).map(|j| (r * 10 + j) as f64).collect();
                w.push_row(&cols, &vals);
            }
            // Pick 0 keeps a row; 1 and 2 take new row 0 (two entries) or 1 (empty).
            let new_rows = [(vec![1u32, 3], vec![-1.0, -2.0]), (vec![], vec![])];
            let fill = |rows: &mut SparseWeights| {
                for (c, v) in &new_rows {
                    rows.push_row(c, v);
                }
            };
            let replaced: Vec<(usize, u32)> = (0..lens.len())
                .filter(|&r| pick[r] > 0)
                .map(|r| (r, pick[r] as u32 - 1))
                .collect();
            let base = Arc::new(w.clone());
            let used = PatchedWeights::new(
                base.clone(),
                PatchBuffers::default(),
                |rows| rows.push_row(&[0, 1, 2], &[0.2, 0.3, 0.5]),
                [(0, 0)],
            );
            let fresh = PatchedWeights::new(base.clone(), PatchBuffers::default(), fill, replaced.clone());
            let reused = PatchedWeights::new(base, used.into_buffers(), fill, replaced);
            let mut want = SparseWeights::empty(4);
            for (r, &p) in pick.iter().enumerate().take(lens.len()) {
                let (c, v) = match p {
                    0 => w.row(r),
                    k => (&new_rows[k - 1].0[..], &new_rows[k - 1].1[..]),
                };
                want.push_row(c, v);
            }
            for patched in [&fresh, &reused] {
                let rows = WeightRows::Patched(patched);
                proptest::prop_assert_eq!(rows.num_rows(), want.num_rows());
                proptest::prop_assert_eq!(rows.num_entries(), want.cols.len());
                proptest::prop_assert_eq!(&rows.to_sparse(), &want);
                proptest::prop_assert_eq!(rows.block_columns(block), want.block_columns(block));
            }
        }
    }

    proptest::proptest! {
        /// Reading every block's columns back into rows gives each row's entries in the
        /// row's own order, for any block size (a partial last block, empty rows).
        #[test]
        fn block_columns_read_back_as_the_rows_in_their_order(
            rows in proptest::collection::vec(proptest::collection::btree_set(0u32..9, 0..5), 0..40),
            block in 1usize..9,
        ) {
            let mut w = SparseWeights::empty(9);
            for (r, cols) in rows.iter().enumerate() {
                let cols: Vec<u32> = cols.iter().copied().collect();
                let vals: Vec<f64> = cols.iter().map(|&c| (r * 16) as f64 + c as f64).collect();
                w.push_row(&cols, &vals);
            }
            let by = w.block_columns(block);
            let mut back: Vec<Vec<(u32, f64)>> = vec![Vec::new(); w.num_rows()];
            for c in 0..w.num_rows().div_ceil(block) {
                let mut last = None;
                for (col, offsets, vals) in by.columns(c) {
                    proptest::prop_assert!(last < Some(col), "columns ascending");
                    last = Some(col);
                    proptest::prop_assert!(offsets.windows(2).all(|o| o[0] < o[1]));
                    for (&o, &v) in offsets.iter().zip(vals) {
                        back[c * block + o as usize].push((col, v));
                    }
                }
            }
            for (r, got) in back.iter().enumerate() {
                let (cols, vals) = w.row(r);
                let want: Vec<(u32, f64)> = cols.iter().copied().zip(vals.iter().copied()).collect();
                proptest::prop_assert_eq!(got, &want);
            }
        }
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
