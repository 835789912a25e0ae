//! Per-bundle index over its tetrahedra: a uniform grid answers "every tet containing this point"
//! (the candidates of LGI), a small bounding-volume hierarchy answers "the tets nearest to this
//! point" for bundles outside every tet (`nearest.rs`). Barycentric frames are precomputed in f64.

use glam::{DMat3, DVec3};

use crate::error::{LgiError, Result};
use crate::prefetch::prefetch;
use crate::tets::{tet_inverse, Tet};

mod nearest;

pub(crate) use nearest::first_nearest;

use nearest::Node;

/// Queries with `eps` up to this use the grid; larger ones scan every tet (exact, O(#tets)).
const FAST_EPS: f64 = 1e-7;
/// Cells are registered with each tet's box grown as for `eps = BUILD_EPS`: the slack over
/// `FAST_EPS` absorbs rounding in the barycentric coordinates of well-shaped tets.
const BUILD_EPS: f64 = 1e-6;
/// At most this many grid cells per bundle (4 bytes each).
const MAX_CELLS: usize = 1 << 18;
/// At most this many (cell, tet) registrations per tet on average (4 bytes each).
const MAX_REGISTRATIONS_PER_TET: usize = 32;
/// Tets sampled to choose the grid resolution.
const SAMPLE_TETS: usize = 512;

/// Marks a flat tet (no usable frame) in [`Incident::tag`].
const FLAT: u32 = 1 << 31;
/// [`Incident::tag`] holds the point's slot in the tet (0..4) from this bit.
const SLOT_SHIFT: u32 = 29;
/// The tet index in [`Incident::tag`]; also the most tets an index holds.
const TET_MASK: u32 = (1 << SLOT_SHIFT) - 1;

/// A tet incident to a point, with its other three corners inline: the projection filters and
/// bounds the tets around a point from the (few, cached) points alone.
#[derive(Debug, Clone, Copy)]
struct Incident {
    /// Tet index | slot of the point in the tet << [`SLOT_SHIFT`] | [`FLAT`] for a flat tet.
    tag: u32,
    /// The tet's corners after the point's slot, cyclically.
    others: [u32; 3],
}

impl Incident {
    fn tet(&self) -> u32 {
        self.tag & TET_MASK
    }

    /// The tet's corners in tet order, given the point's own position `o`.
    fn corners(&self, o: DVec3, points: &[DVec3]) -> [DVec3; 4] {
        let slot = ((self.tag >> SLOT_SHIFT) & 3) as usize;
        let mut c = [o; 4];
        for (k, &w) in self.others.iter().enumerate() {
            c[(slot + 1 + k) % 4] = points[w as usize];
        }
        c
    }
}

/// Affine map from a point to the last three barycentric coordinates of one tet.
#[derive(Debug, Clone, Copy)]
struct BaryMap {
    inv: DMat3,
    p0: DVec3,
}

/// The index of one bundle: its cloud's points, its tets, per-tet inverse barycentric matrices, a
/// uniform grid (CSR lists, per cell, of the tets that may contain a point of the cell) and a box
/// hierarchy for nearest-tet queries. Immutable after construction, `Send + Sync`.
#[derive(Debug, Clone)]
pub struct TetIndex {
    points: Vec<DVec3>,
    tets: Vec<Tet>,
    frames: Vec<BaryMap>,
    /// The grid (`dims == [0; 3]` when no tet is usable) and the top corner of its box.
    grid: Grid,
    hi: DVec3,
    cell_start: Vec<u32>,
    cell_items: Vec<u32>,
    /// The cells listing more than [`DENSE`] tets (ascending), each split into
    /// [`SPLIT`]³ sub-cells with lists of their own (CSR, [`SPLIT`]³ per dense cell).
    dense: Vec<u32>,
    sub_start: Vec<u32>,
    sub_items: Vec<u32>,
    nodes: Vec<Node>,
    bvh_items: Vec<u32>,
    /// Scale of the cloud, for the rounding slack of nearest-tet pruning.
    scale: f64,
    /// Tets incident to each point (CSR), for the fast projection around the nearest points.
    incident_start: Vec<u32>,
    incident: Vec<Incident>,
    /// Extent of the points along each of [`SLAB_DIRECTIONS`] and the cloud's thinnest axis:
    /// a point beyond one of these slabs is outside the hull, so no tet can contain it.
    slabs: Vec<(DVec3, f64, f64)>,
    /// Largest slab width (the cloud's size), scaling the slab margin.
    extent: f64,
}

/// Fixed directions of the slab test (a Fibonacci sphere; opposite directions are redundant).
const SLAB_DIRECTIONS: usize = 48;

/// A cell listing more tets than this is split into sub-cells: near the neutral many small
/// tets crowd into a few cells, and a query there tested ~200 tets to find one.
const DENSE: usize = 48;
/// Sub-cells per axis of a dense cell.
const SPLIT: u32 = 4;
/// The split cells' registrations stay within the grid's own divided by this.
const SPLIT_BUDGET: usize = 2;

/// A uniform grid over a box: `dims` cells of size `1 / inv_cell` from `lo`.
#[derive(Debug, Clone, Copy)]
struct Grid {
    lo: DVec3,
    dims: [u32; 3],
    inv_cell: DVec3,
}

impl Grid {
    const EMPTY: Grid = Grid {
        lo: DVec3::ZERO,
        dims: [0; 3],
        inv_cell: DVec3::ZERO,
    };

    fn cell_coord(&self, x: f64, axis: usize) -> u32 {
        // The cast truncates toward zero and saturates (negative and NaN to 0): `floor`
        // then `max(0)` without the libm call. Then a clamp: monotone in x, so a tet's box
        // and any point inside it always agree on the cells (this makes the grid exact).
        (((x - self.lo[axis]) * self.inv_cell[axis]) as u32).min(self.dims[axis] - 1)
    }

    fn cell_of(&self, p: DVec3) -> [u32; 3] {
        [
            self.cell_coord(p.x, 0),
            self.cell_coord(p.y, 1),
            self.cell_coord(p.z, 2),
        ]
    }

    fn linear(&self, c: [u32; 3]) -> usize {
        (c[2] as usize * self.dims[1] as usize + c[1] as usize) * self.dims[0] as usize
            + c[0] as usize
    }

    /// The cell of linear index `i`.
    fn coords(&self, i: usize) -> [u32; 3] {
        let (nx, ny) = (self.dims[0] as usize, self.dims[1] as usize);
        [
            (i % nx) as u32,
            ((i / nx) % ny) as u32,
            (i / (nx * ny)) as u32,
        ]
    }

    fn num_cells(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    fn cell_size(&self) -> DVec3 {
        DVec3::new(
            1.0 / self.inv_cell.x,
            1.0 / self.inv_cell.y,
            1.0 / self.inv_cell.z,
        )
    }

    /// The grid of [`SPLIT`]³ sub-cells over cell `c`. A point the coarse grid puts in `c`
    /// lies within rounding of the sub-grid's box, and the clamp puts it in a sub-cell.
    fn split(&self, c: [u32; 3]) -> Grid {
        Grid {
            lo: self.lo + DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * self.cell_size(),
            dims: [SPLIT; 3],
            inv_cell: self.inv_cell * SPLIT as f64,
        }
    }
}

impl TetIndex {
    /// Builds the index of `tets` over `points`.
    ///
    /// The grid spans the union of the tets' (slightly grown) bounding boxes. A tet is registered
    /// in each cell of its box that is not wholly beyond one of its face planes. The (near-cubic)
    /// cell size is the finest of a geometric sequence that keeps at most 2¹⁸ cells and about 32
    /// registrations per tet (estimated on a sample of 512 tets); finer cells mean fewer tets
    /// tested per query but more memory. The most crowded cells (over 48 tets) are then split
    /// into 4³ sub-cells each, within half the grid's registrations again. Flat tets (singular
    /// barycentric matrix) are kept in [`tets`](Self::tets) and in
    /// [`nearest`](Self::nearest), but never contain a point.
    ///
    /// Cost: O(#tets × cells per tet box) time; memory ≈ 96 bytes per tet for the barycentric
    /// frames, 16 for the tet, 4 × 16 for the incidence lists (corners inline), ~60 for the
    /// hierarchy and up to 1.5 × 4 × 32 for the grid and its split cells (about 8 MiB for
    /// 20,000 tets).
    ///
    /// Errors: [`LgiError::Input`] when a tet refers to a missing point, a point is not finite,
    /// or there are 2²⁹ tets or more.
    pub fn new(points: Vec<DVec3>, tets: Vec<Tet>) -> Result<Self> {
        if let Some(i) = points.iter().position(|p| !p.is_finite()) {
            return Err(LgiError::Input(format!(
                "tet index: point {i} is not finite: {}",
                points[i]
            )));
        }
        if let Some((t, tet)) = tets
            .iter()
            .enumerate()
            .find(|(_, tet)| tet.iter().any(|&v| v as usize >= points.len()))
        {
            return Err(LgiError::Input(format!(
                "tet index: tet {t} {tet:?} refers to a point beyond the {} points",
                points.len()
            )));
        }
        if tets.len() > TET_MASK as usize {
            return Err(LgiError::Input(format!(
                "tet index: {} tets is more than the 2^29 supported",
                tets.len()
            )));
        }
        let frames: Vec<BaryMap> = tets
            .iter()
            .map(|t| frame(t.map(|v| points[v as usize])))
            .collect();
        let boxes: Vec<(DVec3, DVec3)> = tets
            .iter()
            .map(|t| {
                let v = t.map(|i| points[i as usize]);
                let lo = v[0].min(v[1]).min(v[2]).min(v[3]);
                let hi = v[0].max(v[1]).max(v[2]).max(v[3]);
                (lo, hi)
            })
            .collect();
        let scale = points
            .iter()
            .fold(0.0f64, |m, p| m.max(p.abs().max_element()))
            .max(f64::MIN_POSITIVE);
        let mut incident_start = vec![0u32; points.len() + 1];
        for t in &tets {
            for &v in t {
                incident_start[v as usize + 1] += 1;
            }
        }
        for i in 0..points.len() {
            incident_start[i + 1] += incident_start[i];
        }
        let mut fill = incident_start.clone();
        let mut incident = vec![
            Incident {
                tag: 0,
                others: [0; 3]
            };
            incident_start[points.len()] as usize
        ];
        for (ti, (t, f)) in tets.iter().zip(&frames).enumerate() {
            let flat = if f.inv.is_finite() { 0 } else { FLAT };
            for (j, &v) in t.iter().enumerate() {
                incident[fill[v as usize] as usize] = Incident {
                    tag: ti as u32 | (j as u32) << SLOT_SHIFT | flat,
                    others: [t[(j + 1) % 4], t[(j + 2) % 4], t[(j + 3) % 4]],
                };
                fill[v as usize] += 1;
            }
        }
        let mut index = TetIndex {
            points,
            tets,
            frames,
            incident_start,
            incident,
            grid: Grid::EMPTY,
            hi: DVec3::ZERO,
            cell_start: vec![0],
            cell_items: Vec::new(),
            dense: Vec::new(),
            sub_start: vec![0],
            sub_items: Vec::new(),
            nodes: Vec::new(),
            bvh_items: Vec::new(),
            scale,
            slabs: Vec::new(),
            extent: 0.0,
        };
        index.slabs = slabs(&index.points);
        index.extent = index
            .slabs
            .iter()
            .fold(0.0f64, |m, &(_, lo, hi)| m.max(hi - lo));
        index.build_grid(&boxes);
        index.build_bvh(&boxes);
        Ok(index)
    }

    /// Number of tets.
    pub fn num_tets(&self) -> usize {
        self.tets.len()
    }

    /// The tets, as given to [`new`](Self::new).
    pub fn tets(&self) -> &[Tet] {
        &self.tets
    }

    /// The cloud's points, as given to [`new`](Self::new).
    pub fn points(&self) -> &[DVec3] {
        &self.points
    }

    /// Barycentric coordinates of `p` with respect to tet `t` (sum 1; NaN for a flat tet).
    ///
    /// # Panics
    /// If `t >= self.num_tets()`.
    pub fn barycentric(&self, t: usize, p: DVec3) -> [f64; 4] {
        bary(&self.frames[t], p)
    }

    /// Appends to `out` every tet containing `p` (every barycentric coordinate `>= -eps`) as
    /// `(tet index, barycentric)`, in ascending tet order. A point outside the grid's box, or not
    /// finite, gets nothing. Allocation-free apart from `out`'s growth.
    ///
    /// `eps` is in barycentric units (e.g. `1e-9`). Up to `1e-7` the grid answers, with exactly
    /// the tets a scan of all tets with the same test would give (cells are registered for
    /// `eps = 1e-6`; the slack covers rounding for all but near-flat tets, quality ≲ 1e-8). A
    /// larger `eps` falls back to testing every tet (same answer, O(#tets)).
    pub fn query(&self, p: DVec3, eps: f64, out: &mut Vec<(u32, [f64; 4])>) {
        if !p.is_finite() || self.grid.dims[0] == 0 {
            return;
        }
        let test = |t: u32, out: &mut Vec<(u32, [f64; 4])>| {
            let b = bary(&self.frames[t as usize], p);
            if b.iter().all(|&x| x >= -eps) {
                // The caller reads the corners of every containing tet next.
                prefetch(&self.tets[t as usize]);
                out.push((t, b));
            }
        };
        // NaN eps takes the scan too (and finds nothing).
        if eps.is_nan() || eps > FAST_EPS {
            (0..self.tets.len() as u32).for_each(|t| test(t, out));
            return;
        }
        if p.cmplt(self.grid.lo).any() || p.cmpgt(self.hi).any() {
            return;
        }
        // Outside the hull (with a margin beyond the reach of any `eps` the grid answers):
        // nothing can contain p.
        let margin = (8.0 * FAST_EPS + 1e-12) * self.extent;
        if self
            .slabs
            .iter()
            .any(|&(d, lo, hi)| !(lo - margin..=hi + margin).contains(&p.dot(d)))
        {
            return;
        }
        let c = self.grid.cell_of(p);
        let cell = self.grid.linear(c);
        let (start, end) = (
            self.cell_start[cell] as usize,
            self.cell_start[cell + 1] as usize,
        );
        let mut items = &self.cell_items[start..end];
        if items.len() > DENSE {
            if let Ok(k) = self.dense.binary_search(&(cell as u32)) {
                let sub = self.grid.split(c);
                let i = k * sub.num_cells() + sub.linear(sub.cell_of(p));
                let (start, end) = (self.sub_start[i] as usize, self.sub_start[i + 1] as usize);
                items = &self.sub_items[start..end];
            }
        }
        // The frames are scattered: ask for all of them before testing the first.
        for &t in items {
            prefetch(&self.frames[t as usize]);
        }
        for &t in items {
            test(t, out);
        }
    }

    /// Bytes owned by the index (its vectors' capacities), excluding `size_of::<Self>()`.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.points.capacity() * size_of::<DVec3>()
            + self.tets.capacity() * size_of::<Tet>()
            + self.frames.capacity() * size_of::<BaryMap>()
            + self.cell_start.capacity() * size_of::<u32>()
            + self.cell_items.capacity() * size_of::<u32>()
            + (self.dense.capacity() + self.sub_start.capacity() + self.sub_items.capacity())
                * size_of::<u32>()
            + self.nodes.capacity() * size_of::<Node>()
            + self.bvh_items.capacity() * size_of::<u32>()
            + self.incident_start.capacity() * size_of::<u32>()
            + self.incident.capacity() * size_of::<Incident>()
    }

    /// Grid shape `[nx, ny, nz]` (all 0 when no tet is usable): for diagnostics and benchmarks.
    pub fn grid_dims(&self) -> [u32; 3] {
        self.grid.dims
    }

    /// Total (cell, tet) registrations in the grid: for diagnostics and benchmarks.
    pub fn grid_registrations(&self) -> usize {
        self.cell_items.len()
    }

    /// Dense cells split into sub-cells, and the (sub-cell, tet) registrations there: for
    /// diagnostics and benchmarks.
    pub fn grid_split(&self) -> (usize, usize) {
        (self.dense.len(), self.sub_items.len())
    }

    fn build_grid(&mut self, boxes: &[(DVec3, DVec3)]) {
        // A tet is registered over its box grown as its eps-region would be (the tet scaled by
        // 1 + 4·eps about its centroid), for eps = BUILD_EPS.
        let grown: Vec<Option<(DVec3, DVec3)>> = boxes
            .iter()
            .zip(&self.frames)
            .map(|(&(lo, hi), f)| {
                let margin = (hi - lo) * (4.0 * BUILD_EPS);
                f.inv.is_finite().then_some((lo - margin, hi + margin))
            })
            .collect();
        let Some((lo, hi)) = grown
            .iter()
            .flatten()
            .copied()
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
        else {
            return;
        };
        self.grid.lo = lo;
        self.hi = hi;
        let extent = hi - lo;
        let valid: Vec<usize> = (0..grown.len()).filter(|&t| grown[t].is_some()).collect();
        // Resolution is chosen on a deterministic sample of the tets: the counts scale with it.
        let stride = valid.len().div_ceil(SAMPLE_TETS).max(1);
        let sample = || valid.iter().copied().step_by(stride);
        let sample_len = sample().count();
        let budget = (MAX_REGISTRATIONS_PER_TET * sample_len) as f64;

        // Candidate resolutions: cells along the longest axis, growing by ~1.25x; keep the
        // finest within the memory budget (finer cells always test fewer tets per query).
        let mut dims = [1u32; 3];
        let mut along = 2.0f64;
        loop {
            let h = extent.max_element() / along;
            let candidate = [0, 1, 2].map(|a| ((extent[a] / h).ceil() as u32).max(1));
            let cells = candidate.iter().map(|&d| d as usize).product::<usize>();
            if cells > MAX_CELLS {
                break;
            }
            self.set_dims(candidate);
            let mut registrations = 0usize;
            for_each_registration(&self.grid, &self.frames, &grown, sample(), |_, _| {
                registrations += 1
            });
            if registrations as f64 > budget {
                break;
            }
            dims = candidate;
            along = (along * 1.25).ceil();
        }
        self.set_dims(dims);
        let mut pairs = Vec::new();
        let all = 0..grown.len();
        for_each_registration(&self.grid, &self.frames, &grown, all.clone(), |t, cell| {
            pairs.push((cell, t))
        });
        if u32::try_from(pairs.len()).is_err() {
            // Only for billions of tets: one cell keeps the offsets within u32.
            self.set_dims([1, 1, 1]);
            pairs.clear();
            for_each_registration(&self.grid, &self.frames, &grown, all, |t, cell| {
                pairs.push((cell, t))
            });
        }
        (self.cell_start, self.cell_items) = by_cell(self.grid.num_cells(), &pairs);
        self.split_dense_cells(&grown);
    }

    /// Splits the cells listing more than [`DENSE`] tets into [`SPLIT`]³ sub-cells, each
    /// listing the tets of its cell registered there as in [`build_grid`](Self::build_grid)
    /// (the same exactness argument on the finer grid). The most crowded cells go first, until
    /// the sub-cell lists would outgrow half the cells' own: a memory budget, as each doubling
    /// of it saves fewer tested tets (docs/journal/2026-12-02.md has the trade measured).
    fn split_dense_cells(&mut self, grown: &[Option<(DVec3, DVec3)>]) {
        let grid = self.grid;
        // (Never for usable tets, which have volume: a cell of no size has nothing to split.)
        if !grid.inv_cell.cmpgt(DVec3::ZERO).all() || !grid.inv_cell.is_finite() {
            return;
        }
        let count = |c: usize| (self.cell_start[c + 1] - self.cell_start[c]) as usize;
        let mut crowded: Vec<usize> = (0..grid.num_cells())
            .filter(|&c| count(c) > DENSE)
            .collect();
        crowded.sort_by_key(|&c| (std::cmp::Reverse(count(c)), c));
        let mut budget = self.cell_items.len() / SPLIT_BUDGET;
        let mut split = Vec::new();
        let mut pairs = Vec::new();
        for cell in crowded {
            let sub = grid.split(grid.coords(cell));
            let (start, end) = (self.cell_start[cell], self.cell_start[cell + 1]);
            let tets = self.cell_items[start as usize..end as usize]
                .iter()
                .map(|&t| t as usize);
            pairs.clear();
            for_each_registration(&sub, &self.frames, grown, tets, |t, c| pairs.push((c, t)));
            if pairs.len() > budget {
                break;
            }
            budget -= pairs.len();
            split.push((cell as u32, by_cell(sub.num_cells(), &pairs)));
        }
        split.sort_unstable_by_key(|s| s.0);
        for (cell, (sub_start, sub_items)) in split {
            let base = self.sub_items.len() as u32;
            self.sub_start
                .extend(sub_start[1..].iter().map(|&s| base + s));
            self.sub_items.extend_from_slice(&sub_items);
            self.dense.push(cell);
        }
    }

    fn set_dims(&mut self, dims: [u32; 3]) {
        let extent = self.hi - self.grid.lo;
        self.grid.dims = dims;
        self.grid.inv_cell = DVec3::new(
            cell_inverse(dims[0], extent.x),
            cell_inverse(dims[1], extent.y),
            cell_inverse(dims[2], extent.z),
        );
    }
}

/// CSR lists per cell of `(cell, tet)` pairs, by a counting sort: pairs come in ascending tet
/// order, so every cell's list is sorted and queries need no sort.
fn by_cell(cells: usize, pairs: &[(usize, u32)]) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; cells + 1];
    for &(cell, _) in pairs {
        start[cell + 1] += 1;
    }
    for c in 0..cells {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; pairs.len()];
    for &(cell, t) in pairs {
        items[fill[cell] as usize] = t;
        fill[cell] += 1;
    }
    (start, items)
}

/// Calls `f(tet, cell)` for every cell a tet's eps-region may reach: the cells of its grown
/// box, minus those lying wholly beyond one of its face planes (by more than `BUILD_EPS`).
/// The plane test is what keeps thin tets out of most cells of their box.
fn for_each_registration(
    grid: &Grid,
    frames: &[BaryMap],
    grown: &[Option<(DVec3, DVec3)>],
    tets: impl Iterator<Item = usize>,
    mut f: impl FnMut(u32, usize),
) {
    let cell = grid.cell_size();
    // Half a cell, grown so rounding in `cell_of` never puts a point outside its cell's box.
    let half = cell * (0.5 + 1e-9);
    for t in tets {
        let Some((lo, hi)) = grown[t] else { continue };
        let frame = &frames[t];
        let rows = [frame.inv.row(0), frame.inv.row(1), frame.inv.row(2)];
        // |grad λ_i| · half: how much λ_i can rise from a cell's centre to its corners.
        let reach = [
            (rows[0] + rows[1] + rows[2]).abs().dot(half),
            rows[0].abs().dot(half),
            rows[1].abs().dot(half),
            rows[2].abs().dot(half),
        ];
        let a = grid.cell_of(lo);
        let b = grid.cell_of(hi);
        // λ is affine: step it along x from each row's first centre instead of recomputing
        // it per cell (the drift is ~1e-15, far inside the BUILD_EPS − FAST_EPS slack).
        let dx = frame.inv * DVec3::new(cell.x, 0.0, 0.0);
        let step = [-(dx.x + dx.y + dx.z), dx.x, dx.y, dx.z];
        for z in a[2]..=b[2] {
            for y in a[1]..=b[1] {
                let centre =
                    grid.lo + DVec3::new(a[0] as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * cell;
                let mut l = bary(frame, centre);
                let row = grid.linear([a[0], y, z]);
                for x in a[0]..=b[0] {
                    if (0..4).all(|i| l[i] + reach[i] >= -BUILD_EPS) {
                        f(t as u32, row + (x - a[0]) as usize);
                    }
                    for i in 0..4 {
                        l[i] += step[i];
                    }
                }
            }
        }
    }
}

fn cell_inverse(dims: u32, extent: f64) -> f64 {
    let inv = dims as f64 / extent;
    if inv.is_finite() {
        inv
    } else {
        0.0
    }
}

fn frame(v: [DVec3; 4]) -> BaryMap {
    BaryMap {
        // NaN makes every containment test false for a flat tet.
        inv: tet_inverse(v).unwrap_or(DMat3::NAN),
        p0: v[0],
    }
}

#[inline]
fn bary(f: &BaryMap, p: DVec3) -> [f64; 4] {
    let l = f.inv * (p - f.p0);
    [1.0 - l.x - l.y - l.z, l.x, l.y, l.z]
}

/// The slabs of [`TetIndex`]: for each direction, the extent of `points` along it.
fn slabs(points: &[DVec3]) -> Vec<(DVec3, f64, f64)> {
    if points.is_empty() {
        return Vec::new();
    }
    let mut dirs: Vec<DVec3> = (0..SLAB_DIRECTIONS)
        .map(|i| {
            // Half a Fibonacci sphere (y >= 0): the other half gives the same slabs.
            let y = 1.0 - (i as f64 + 0.5) / SLAB_DIRECTIONS as f64;
            let r = (1.0 - y * y).sqrt();
            let phi = i as f64 * 2.399_963_229_728_653;
            DVec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect();
    // The thinnest principal axis (inverse power iteration on the covariance): clouds of
    // bundles that move in little more than a plane have noisy targets just off that plane.
    let c = points.iter().copied().sum::<DVec3>() / points.len() as f64;
    let cov = points.iter().fold(DMat3::ZERO, |m, p| {
        let q = *p - c;
        m + DMat3::from_cols(q * q.x, q * q.y, q * q.z)
    });
    let inv = cov.inverse();
    if inv.is_finite() {
        let mut v = DVec3::new(0.267, 0.535, 0.802);
        for _ in 0..32 {
            v = (inv * v).normalize_or_zero();
        }
        if v != DVec3::ZERO {
            dirs.push(v);
        }
    }
    dirs.into_iter()
        .map(|d| {
            let (lo, hi) = points
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    let x = p.dot(d);
                    (lo.min(x), hi.max(x))
                });
            (d, lo, hi)
        })
        .collect()
}

#[cfg(test)]
mod tests;
