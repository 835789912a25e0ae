//! Sparse row-major (CSR) weights over sites: the V×B sewing matrix W, the Sibson rows it is
//! built from and the plans for missing markers. One general type so those stages share it;
//! `sanity_check` states its invariants for tests and fuzzers.

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

    /// These rows with some replaced, written into `out`'s buffers (its contents dropped,
    /// its memory reused: a take with a new missing set every frame then copies into memory
    /// it has touched before rather than fresh pages the kernel must clear). `replacement(r)`
    /// is row r's new columns and weights, or `None` to keep it; the runs of kept rows are
    /// copied whole. (Serial: in a solve the other threads are choosing the next frame, and
    /// a parallel copy measured no faster there.)
    pub fn with_rows_replaced<'r>(
        &self,
        replacement: impl Fn(usize) -> Option<Row<'r>>,
        mut out: SparseWeights,
    ) -> SparseWeights {
        out.row_start.clear();
        out.cols.clear();
        out.vals.clear();
        out.num_cols = self.num_cols;
        out.row_start.reserve(self.row_start.len());
        out.cols.reserve(self.cols.len());
        out.vals.reserve(self.vals.len());
        out.row_start.push(0);
        let n = self.num_rows();
        let mut next = 0;
        for end in 0..=n {
            // A kept row extends the run; a replaced one, or the end, closes it.
            let row = if end < n { replacement(end) } else { None };
            if end < n && row.is_none() {
                continue;
            }
            // Rows next..end unchanged: their entries in one copy, their starts shifted.
            let (a, b) = (self.row_start[next] as usize, self.row_start[end] as usize);
            let at = out.cols.len();
            out.cols.extend_from_slice(&self.cols[a..b]);
            out.vals.extend_from_slice(&self.vals[a..b]);
            let starts = &self.row_start[next + 1..=end];
            out.row_start
                .extend(starts.iter().map(|&s| (s as usize - a + at) as u32));
            if let Some((cols, vals)) = row {
                out.push_row(cols, vals);
            }
            next = end + 1;
        }
        out
    }

    /// These weights by column within blocks of `block` consecutive rows ([`BlockColumns`]).
    pub fn block_columns(&self, block: usize) -> BlockColumns {
        let mut out = BlockColumns::new(block);
        out.rows.reserve(self.cols.len());
        out.vals.reserve(self.cols.len());
        let n = self.num_rows();
        let mut count = Vec::new();
        for first in (0..n).step_by(out.block) {
            out.push_block(self, first, (first + out.block).min(n), &mut count);
        }
        out
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
    fn push_block(&mut self, w: &SparseWeights, first: usize, last: usize, count: &mut Vec<u32>) {
        let last = last.min(first + self.block);
        let (a, b) = (w.row_start[first] as usize, w.row_start[last] as usize);
        count.clear();
        count.resize(w.num_cols, 0);
        for &c in &w.cols[a..b] {
            count[c as usize] += 1;
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
        self.rows.resize(base + (b - a), 0);
        self.vals.resize(base + (b - a), 0.0);
        for r in first..last {
            let (s, e) = (w.row_start[r] as usize, w.row_start[r + 1] as usize);
            for (&c, &v) in w.cols[s..e].iter().zip(&w.vals[s..e]) {
                let slot = &mut count[c as usize];
                self.rows[*slot as usize] = (r - first) as u16;
                self.vals[*slot as usize] = v;
                *slot += 1;
            }
        }
        self.block_start.push(self.col.len() as u32);
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
        /// Replacing any ascending subset of rows (first, last, neighbours, empty rows) gives
        /// the matrix rebuilt row by row with those rows swapped in.
        #[test]
        fn rows_replaced_equal_the_matrix_rebuilt_row_by_row(
            lens in proptest::collection::vec(0usize..4, 1..12),
            pick in proptest::collection::vec(proptest::bool::ANY, 12),
            new_len in 0usize..4,
        ) {
            let mut w = SparseWeights::empty(4);
            for (r, &n) in lens.iter().enumerate() {
                let cols: Vec<u32> = (0..n as u32).collect();
                let vals: Vec<f64> = (0..n).map(|j| (r * 10 + j) as f64).collect();
                w.push_row(&cols, &vals);
            }
            let cols: Vec<u32> = (0..new_len as u32).collect();
            let vals: Vec<f64> = (0..new_len).map(|j| -1.0 - j as f64).collect();
            let rows = |r: usize| pick[r].then_some((&cols[..], &vals[..]));
            let got = w.with_rows_replaced(rows, SparseWeights::empty(4));
            let mut want = SparseWeights::empty(4);
            for (r, &swap) in pick.iter().enumerate().take(lens.len()) {
                let (c, v) = if swap { (&cols[..], &vals[..]) } else { w.row(r) };
                want.push_row(c, v);
            }
            // Written into another matrix's buffers: that matrix's contents are gone.
            let mut used = SparseWeights::empty(7);
            used.push_row(&[5, 6], &[0.5, 0.5]);
            let into = w.with_rows_replaced(rows, used);
            proptest::prop_assert_eq!(&got, &want);
            proptest::prop_assert_eq!(into, want);
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
