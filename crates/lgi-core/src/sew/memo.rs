//! Rows kept for the plans of missing sets: the sewn rows that a few missing bundles (one or
//! two) change, with them missing, computed the first time a frame needs them (every single
//! bundle's at once) and kept for the take's later frames, so that a plan's cost falls as a
//! take goes on however many distinct missing sets it has: only rows that more missing
//! bundles share, or that no earlier frame needed, are computed for it.

use super::context::SewContext;
use crate::error::Result;
use crate::hash::FastMap;
use crate::sparse::SparseWeights;
use rayon::prelude::*;
use std::hash::{Hash, Hasher};
use std::sync::{Arc, Mutex, OnceLock};

/// Rows kept for sets of two or more in all (about 200 bytes each) before those are cleared.
const SET_ROWS: usize = 1 << 18;

/// A set's rows kept in more pieces than this are merged into one.
const MERGE_PIECES: usize = 4;

/// Most bundles a kept row is without: rows that more missing bundles touch are recomputed
/// for each plan. Two: sets of three or more missing markers seldom repeat, so keeping their
/// rows too made frames slower (measured: docs/journal/2026-12-02.md).
pub(crate) const MAX_GONE: usize = 2;

/// Which bundles a kept row is without: one to [`MAX_GONE`], ascending.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Gone {
    bundles: [u32; MAX_GONE],
    len: u8,
}

impl Gone {
    /// Bundle `b` alone.
    pub(crate) fn one(b: u32) -> Gone {
        let mut bundles = [0; MAX_GONE];
        bundles[0] = b;
        Gone { bundles, len: 1 }
    }

    /// These bundles and `b`, if that is at most [`MAX_GONE`] (the same when `b` is one).
    pub(crate) fn with(self, b: u32) -> Option<Gone> {
        if self.has(b) {
            return Some(self);
        }
        let n = self.len as usize;
        if n == MAX_GONE {
            return None;
        }
        let mut out = self;
        let at = self.bundles[..n].partition_point(|&x| x < b);
        out.bundles.copy_within(at..n, at + 1);
        out.bundles[at] = b;
        out.len += 1;
        Some(out)
    }

    /// True when `b` is one of the bundles.
    pub(crate) fn has(self, b: u32) -> bool {
        self.bundles().contains(&b)
    }

    /// The bundles, ascending.
    pub(crate) fn bundles(&self) -> &[u32] {
        &self.bundles[..self.len as usize]
    }

    /// The bundle when there is one.
    pub(crate) fn single(self) -> Option<u32> {
        (self.len == 1).then_some(self.bundles[0])
    }
}

impl Hash for Gone {
    fn hash<H: Hasher>(&self, h: &mut H) {
        for &b in self.bundles() {
            h.write_u32(b);
        }
    }
}

/// A map keyed by [`Gone`] (a plan looks one up for about every other row it takes from the
/// kept ones).
pub(crate) type GoneMap<V> = FastMap<Gone, V>;

/// Some sewn rows with the bundles of a [`Gone`] missing.
#[derive(Debug)]
pub(crate) struct Rows {
    /// The sewn rows (ascending).
    rows: Vec<u32>,
    /// Their rows as [`SewContext::rows_for`] makes them without those bundles.
    pub(crate) weights: SparseWeights,
    /// Every column their Sibson rows had before barriers and detours (natural neighbours, or
    /// the hull edge's ends): which other missing bundle could change them.
    pub(crate) support: SparseWeights,
}

impl Rows {
    /// The sewn rows `rows` (ascending; `sewn` maps them to vertices) with the bundles `gone`
    /// missing.
    fn without(ctx: &SewContext<'_>, gone: &[u32], rows: Vec<u32>, sewn: &[u32]) -> Result<Rows> {
        let nb = ctx.bundles.len() as u32;
        let present: Vec<u32> = (0..nb).filter(|b| !gone.contains(b)).collect();
        let vertices: Vec<usize> = rows.iter().map(|&r| sewn[r as usize] as usize).collect();
        let (weights, support) = ctx.rows_and_support_for(&present, &vertices)?;
        Ok(Rows {
            rows,
            weights,
            support,
        })
    }

    /// Index of sewn row `r` among these rows.
    pub(crate) fn find(&self, r: u32) -> Option<usize> {
        self.rows.binary_search(&r).ok()
    }

    /// The rows of `pieces` in one, ascending (a row kept twice, by plans made at the same
    /// time, is the same row: the first is kept).
    fn merged(pieces: &[Arc<Rows>]) -> Rows {
        let mut order: Vec<(u32, usize, usize)> = Vec::new();
        for (p, piece) in pieces.iter().enumerate() {
            order.extend(piece.rows.iter().enumerate().map(|(i, &r)| (r, p, i)));
        }
        order.sort_unstable();
        order.dedup_by_key(|e| e.0);
        let num_cols = pieces.first().map_or(0, |p| p.weights.num_cols);
        let mut out = Rows {
            rows: Vec::with_capacity(order.len()),
            weights: SparseWeights::empty(num_cols),
            support: SparseWeights::empty(num_cols),
        };
        for &(r, p, i) in &order {
            out.rows.push(r);
            let (cols, vals) = pieces[p].weights.row(i);
            out.weights.push_row(cols, vals);
            let (cols, vals) = pieces[p].support.row(i);
            out.support.push_row(cols, vals);
        }
        out
    }
}

/// The kept rows, shared by the plans of all frames: each bundle's (all the rows it touches,
/// made once), and sets' of two or more (the rows asked for so far, bounded).
#[derive(Debug)]
pub(crate) struct RowMemo {
    one: Vec<OnceLock<Arc<Rows>>>,
    sets: Mutex<Sets>,
}

#[derive(Debug, Default)]
struct Sets {
    rows: GoneMap<Vec<Arc<Rows>>>,
    count: usize,
}

impl RowMemo {
    /// An empty memo for `num_bundles` bundles.
    pub(crate) fn new(num_bundles: usize) -> RowMemo {
        RowMemo {
            one: (0..num_bundles).map(|_| OnceLock::new()).collect(),
            sets: Mutex::new(Sets::default()),
        }
    }

    /// Rows kept without one bundle and without pairs.
    #[cfg(test)]
    pub(crate) fn kept_rows(&self) -> (usize, usize) {
        let ones = self
            .one
            .iter()
            .filter_map(|c| c.get())
            .map(|r| r.rows.len())
            .sum();
        (ones, self.sets.lock().map_or(0, |p| p.count))
    }

    /// The rows kept without bundle `m` alone, once made: every row `m` touches, in the
    /// order of its `touching` list.
    pub(crate) fn without_one(&self, m: u32) -> Option<&Rows> {
        self.one.get(m as usize)?.get().map(|rows| &**rows)
    }

    /// A plan's view of the memo.
    pub(crate) fn view(&self) -> View<'_> {
        View {
            memo: self,
            sets: GoneMap::default(),
        }
    }
}

/// One plan's view of a [`RowMemo`]: the sets it has looked up, so that the memo's lock is
/// taken once per set and not once per row.
pub(crate) struct View<'m> {
    memo: &'m RowMemo,
    sets: GoneMap<Vec<Arc<Rows>>>,
}

impl View<'_> {
    /// Sewn row `r` without `gone`, if kept: its rows and index there.
    pub(crate) fn find(&mut self, gone: Gone, r: u32) -> Option<(&Arc<Rows>, usize)> {
        if let Some(m) = gone.single() {
            let rows = self.memo.one.get(m as usize)?.get()?;
            return rows.find(r).map(|i| (rows, i));
        }
        let memo = self.memo;
        let pieces = self.sets.entry(gone).or_insert_with(|| {
            memo.sets
                .lock()
                .ok()
                .and_then(|p| p.rows.get(&gone).cloned())
                .unwrap_or_default()
        });
        pieces.iter().find_map(|p| p.find(r).map(|i| (p, i)))
    }

    /// Computes and keeps the rows `rows` (sewn rows, ascending) without `gone`; a single
    /// bundle keeps every row it touches (`touching`) instead, as it will be missing again.
    /// The first time any single bundle is asked for, every bundle's rows are made at once
    /// (in parallel; a take with one missing marker soon has others).
    pub(crate) fn compute(
        &mut self,
        ctx: &SewContext<'_>,
        gone: Gone,
        rows: Vec<u32>,
        touching: &[Vec<u32>],
        sewn: &[u32],
    ) -> Result<()> {
        if gone.single().is_some() {
            let made: Vec<Result<()>> = (0..self.memo.one.len() as u32)
                .into_par_iter()
                .filter(|&m| self.memo.one[m as usize].get().is_none())
                .map(|m| {
                    let rows = touching[m as usize].clone();
                    let kept = Rows::without(ctx, &[m], rows, sewn)?;
                    // Another frame may have set it meanwhile: the same rows either way.
                    let _ = self.memo.one[m as usize].set(Arc::new(kept));
                    Ok(())
                })
                .collect();
            return made.into_iter().collect();
        }
        let kept = Arc::new(Rows::without(ctx, gone.bundles(), rows, sewn)?);
        self.sets.entry(gone).or_default().push(kept.clone());
        if let Ok(mut sets) = self.memo.sets.lock() {
            let added = kept.rows.len();
            if sets.count + added > SET_ROWS {
                sets.rows.clear();
                sets.count = 0;
            }
            let pieces = sets.rows.entry(gone).or_default();
            pieces.push(kept);
            let mut count = added;
            if pieces.len() > MERGE_PIECES {
                let before: usize = pieces.iter().map(|p| p.rows.len()).sum();
                let merged = Rows::merged(pieces);
                count = (added + merged.rows.len()).saturating_sub(before);
                *pieces = vec![Arc::new(merged)];
            }
            sets.count += count;
        }
        Ok(())
    }
}
