//! Per-bundle index over its tetrahedra: a uniform grid answers "every tet containing this point"
//! (the candidates of LGI), a small bounding-volume hierarchy answers "the tets nearest to this
//! point" for bundles outside every tet. Barycentric frames are precomputed in f64.

use glam::{DMat3, DVec3};

use crate::error::{LgiError, Result};
use crate::prefetch::prefetch;
use crate::tets::{closest_point_in_tet_with, tet_inverse, Tet};

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
/// Tets per leaf of the nearest-tet hierarchy.
const LEAF_SIZE: usize = 4;
/// Fixed traversal stack: the median-split hierarchy is at most ~33 levels deep for 2³² tets.
const STACK: usize = 96;

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

/// How many candidates ahead the projection prefetches a frame.
const LOOKAHEAD: usize = 4;

/// Affine map from a point to the last three barycentric coordinates of one tet.
#[derive(Debug, Clone, Copy)]
struct BaryMap {
    inv: DMat3,
    p0: DVec3,
}

#[derive(Debug, Clone, Copy)]
struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first position in `bvh_items`; inner: index of the left child (right = left + 1).
    first: u32,
    /// Leaf: number of tets (> 0); inner: 0.
    count: u32,
}

/// The index of one bundle: its cloud's points, its tets, per-tet inverse barycentric matrices, a
/// uniform grid (CSR lists, per cell, of the tets that may contain a point of the cell) and a box
/// hierarchy for nearest-tet queries. Immutable after construction, `Send + Sync`.
#[derive(Debug, Clone)]
pub struct TetIndex {
    points: Vec<DVec3>,
    tets: Vec<Tet>,
    frames: Vec<BaryMap>,
    /// Grid box and shape; `dims == [0; 3]` when no tet is usable.
    lo: DVec3,
    hi: DVec3,
    dims: [u32; 3],
    inv_cell: DVec3,
    cell_start: Vec<u32>,
    cell_items: Vec<u32>,
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

impl TetIndex {
    /// Builds the index of `tets` over `points`.
    ///
    /// The grid spans the union of the tets' (slightly grown) bounding boxes. A tet is registered
    /// in each cell of its box that is not wholly beyond one of its face planes. The (near-cubic)
    /// cell size is the finest of a geometric sequence that keeps at most 2¹⁸ cells and about 32
    /// registrations per tet (estimated on a sample of 512 tets); finer cells mean fewer tets
    /// tested per query but more memory. Flat tets (singular barycentric matrix) are kept in
    /// [`tets`](Self::tets) and in [`nearest`](Self::nearest), but never contain a point.
    ///
    /// Cost: O(#tets × cells per tet box) time; memory ≈ 96 bytes per tet for the barycentric
    /// frames, 16 for the tet, 4 × 16 for the incidence lists (corners inline), ~60 for the
    /// hierarchy and ~4 × 32 for the grid (about 7 MiB for 20,000 tets).
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
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
            dims: [0; 3],
            inv_cell: DVec3::ZERO,
            cell_start: vec![0],
            cell_items: Vec::new(),
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

    /// The unpruned reference of [`project_around`](Self::project_around) (tests only): the
    /// tets incident to the `k` cloud points nearest to `p`, each with its closest point to `p`
    /// (barycentric, distance), appended to `out` sorted by distance then tet index.
    #[cfg(test)]
    pub(crate) fn nearest_around(&self, p: DVec3, k: usize, out: &mut Vec<(u32, [f64; 4], f64)>) {
        let base = out.len();
        let k = k.min(self.points.len());
        if k == 0 {
            return;
        }
        let project = |t: u32, out: &mut Vec<(u32, [f64; 4], f64)>| {
            let corners = self.tets[t as usize].map(|i| self.points[i as usize]);
            let inv = &self.frames[t as usize].inv;
            let (q, b) = closest_point_in_tet_with(p, corners, inv.is_finite().then_some(inv));
            out.push((t, b, p.distance(q)));
        };
        if k == 1 {
            // The common case, without allocating: the nearest point (ties: lowest index).
            let v = self.nearest_point(p);
            let (s, e) = (self.incident_start[v], self.incident_start[v + 1]);
            for inc in &self.incident[s as usize..e as usize] {
                project(inc.tet(), out);
            }
        } else {
            let mut near: Vec<(f64, u32)> = self
                .points
                .iter()
                .enumerate()
                .map(|(i, q)| (q.distance_squared(p), i as u32))
                .collect();
            near.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let mut tets: Vec<u32> = near[..k]
                .iter()
                .flat_map(|&(_, v)| {
                    let (s, e) = (
                        self.incident_start[v as usize],
                        self.incident_start[v as usize + 1],
                    );
                    self.incident[s as usize..e as usize]
                        .iter()
                        .map(Incident::tet)
                })
                .collect();
            // Tets shared by several of the points appear once per point.
            tets.sort_unstable();
            tets.dedup();
            for t in tets {
                project(t, out);
            }
        }
        out[base..].sort_unstable_by(|a, b| a.2.total_cmp(&b.2).then(a.0.cmp(&b.0)));
    }

    /// Projection of a target outside every tet: the `n` tets nearest to `p`, among those
    /// incident to the cloud point nearest to `p` (ties: lowest index), whose closest point to
    /// `p` is not one of their vertices (that point is scored on its own) — appended to `out`
    /// sorted by distance then tet index, with the closest point's barycentric and distance.
    /// Not the exact `n` nearest tets of [`nearest`](Self::nearest) — which must enumerate
    /// every tet tied at a shared vertex — but the tets around where `p` left the cloud. Exact
    /// closest points are computed only for tets whose face-plane lower bound can still beat
    /// the current `n`-th distance (`bounds` is scratch); a test checks the result equals
    /// projecting every incident tet.
    pub fn project_around(
        &self,
        p: DVec3,
        n: usize,
        bounds: &mut Vec<(f64, u32)>,
        out: &mut Vec<(u32, [f64; 4], f64)>,
    ) {
        let base = out.len();
        if n == 0 || self.points.is_empty() || !p.is_finite() {
            return;
        }
        let v = self.nearest_point(p);
        let (s, e) = (self.incident_start[v], self.incident_start[v + 1]);
        let o = self.points[v];
        let pv = p - o;
        // The corner test's margin, squared: pv·e < −1e-9 |pv| |e| without square roots.
        let margin2 = 1e-18 * pv.length_squared();
        let incident = &self.incident[s as usize..e as usize];
        bounds.clear();
        // Filter and bound from the inline corners, without loading the tets or their frames.
        bounds.extend(incident.iter().enumerate().filter_map(|(i, inc)| {
            let c = inc.others.map(|w| self.points[w as usize]);
            // The closest point is certainly the corner itself when pv makes an obtuse angle,
            // with margin, with every edge leaving it (pv lies in the tet's normal cone there);
            // such tets are dropped (the corner is scored on its own), borderline ones kept.
            let corner = (0..3).all(|j| {
                let e = c[j] - o;
                let d = pv.dot(e);
                inc.others[j] as usize == v || (d < 0.0 && d * d > margin2 * e.length_squared())
            });
            if corner {
                return None;
            }
            let lb = if inc.tag & FLAT != 0 {
                0.0
            } else {
                plane_lower_bound([o, c[0], c[1], c[2]], p)
            };
            Some((lb, i as u32))
        }));
        // The n lowest bounds first (a tight n-th distance early), the rest in any order: a
        // tet is skipped only when its bound exceeds the n-th distance, which only shrinks.
        if bounds.len() > n {
            // Bounds are finite and ≥ 0, so their bits order as the numbers do.
            bounds.select_nth_unstable_by_key(n - 1, |a| a.0.to_bits());
        }
        // Rounding slack so a bound never prunes a tet whose computed distance ties.
        let slack = 1e-12 * (self.scale + p.abs().max_element());
        // The frames are scattered: ask early for those of the n lowest bounds (always
        // projected), and for the rest a few tets ahead, if not pruned by then.
        let frame_of = |i: u32| &self.frames[incident[i as usize].tet() as usize];
        for &(_, i) in bounds.iter().take(n) {
            prefetch(frame_of(i));
        }
        for (k, &(lb, i)) in bounds.iter().enumerate() {
            let full = out.len() - base == n;
            if let Some(&(ahead_lb, ahead)) =
                bounds.get(k + LOOKAHEAD).filter(|_| k + LOOKAHEAD >= n)
            {
                if !full || ahead_lb - slack <= out[out.len() - 1].2 {
                    prefetch(frame_of(ahead));
                }
            }
            if full && lb - slack > out[out.len() - 1].2 {
                continue;
            }
            let inc = &incident[i as usize];
            let t = inc.tet();
            let corners = inc.corners(o, &self.points);
            let inv = &self.frames[t as usize].inv;
            let (q, b) = closest_point_in_tet_with(p, corners, inv.is_finite().then_some(inv));
            if b.iter().all(|&x| x < 1.0 - 1e-12) {
                // The caller may read the corners of the nearest tets next.
                prefetch(&self.tets[t as usize]);
                insert_nearest(out, base, n, (t, b, p.distance(q)));
            }
        }
    }

    /// The cloud point nearest to `p` (ties: lowest index); 0 for an empty cloud.
    fn nearest_point(&self, p: DVec3) -> usize {
        (0..self.points.len())
            .min_by(|&a, &b| {
                let (da, db) = (
                    self.points[a].distance_squared(p),
                    self.points[b].distance_squared(p),
                );
                da.total_cmp(&db).then(a.cmp(&b))
            })
            .unwrap_or(0)
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
        if !p.is_finite() || self.dims[0] == 0 {
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
        if p.cmplt(self.lo).any() || p.cmpgt(self.hi).any() {
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
        let c = self.cell_of(p);
        let cell = self.linear(c);
        let (start, end) = (
            self.cell_start[cell] as usize,
            self.cell_start[cell + 1] as usize,
        );
        let items = &self.cell_items[start..end];
        // The frames are scattered: ask for all of them before testing the first.
        for &t in items {
            prefetch(&self.frames[t as usize]);
        }
        for &t in items {
            test(t, out);
        }
    }

    /// Appends to `out` the `n` tets nearest to `p` — by distance from `p` to the tet solid — as
    /// `(tet index, barycentric of the closest point, distance)`, sorted by distance then tet
    /// index (tets containing `p` come first, at distance 0). Meant for points outside every tet.
    /// Distances and barycentrics are exactly those of
    /// [`closest_point_in_tet`](crate::tets::closest_point_in_tet).
    ///
    /// Branch and bound over a median-split box hierarchy (nearer child first, boxes farther than
    /// the current `n`-th pruned), allocation-free apart from `out`'s growth. Its cost grows with
    /// the number of tets within the `n`-th distance, ties included: overlapping tets often share
    /// the cloud vertex nearest to `p`, so hundreds of exact tests are usual (tens of µs for
    /// 20,000 tets). A non-finite `p` gets nothing.
    pub fn nearest(&self, p: DVec3, n: usize, out: &mut Vec<(u32, [f64; 4], f64)>) {
        if n == 0 || self.nodes.is_empty() || !p.is_finite() {
            return;
        }
        let base = out.len();
        // Rounding slack so a box bound never prunes a tet whose computed distance ties.
        let slack = 1e-12 * (self.scale + p.abs().max_element());
        let mut stack = [(0u32, 0.0f64); STACK];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let (node_index, bound) = stack[top];
            let full = out.len() - base == n;
            if full && bound > out[out.len() - 1].2 + slack {
                continue;
            }
            let node = self.nodes[node_index as usize];
            if node.count > 0 {
                self.visit_leaf(&node, p, n, base, slack, out);
                continue;
            }
            let left = node.first;
            let right = left + 1;
            let dl = box_distance(p, &self.nodes[left as usize]);
            let dr = box_distance(p, &self.nodes[right as usize]);
            // Nearer child on top so it is searched first and tightens the bound early.
            let (near, far) = if dl <= dr {
                ((left, dl), (right, dr))
            } else {
                ((right, dr), (left, dl))
            };
            if top + 2 <= STACK {
                stack[top] = far;
                stack[top + 1] = near;
                top += 2;
            } else {
                // Unreachable for median splits; scan the subtree's tets rather than lose them.
                for child in [near.0, far.0] {
                    self.scan_subtree(child, p, n, base, out);
                }
            }
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
            + self.nodes.capacity() * size_of::<Node>()
            + self.bvh_items.capacity() * size_of::<u32>()
            + self.incident_start.capacity() * size_of::<u32>()
            + self.incident.capacity() * size_of::<Incident>()
    }

    /// Grid shape `[nx, ny, nz]` (all 0 when no tet is usable): for diagnostics and benchmarks.
    pub fn grid_dims(&self) -> [u32; 3] {
        self.dims
    }

    /// Total (cell, tet) registrations in the grid: for diagnostics and benchmarks.
    pub fn grid_registrations(&self) -> usize {
        self.cell_items.len()
    }

    fn scan_subtree(
        &self,
        node: u32,
        p: DVec3,
        n: usize,
        base: usize,
        out: &mut Vec<(u32, [f64; 4], f64)>,
    ) {
        let node = self.nodes[node as usize];
        if node.count > 0 {
            self.visit_leaf(&node, p, n, base, f64::INFINITY, out);
        } else {
            self.scan_subtree(node.first, p, n, base, out);
            self.scan_subtree(node.first + 1, p, n, base, out);
        }
    }

    /// Offers a leaf's tets to the running best `n`, skipping those whose own box is already
    /// farther than the current `n`-th (the exact distance costs ~10x the box bound).
    fn visit_leaf(
        &self,
        node: &Node,
        p: DVec3,
        n: usize,
        base: usize,
        slack: f64,
        out: &mut Vec<(u32, [f64; 4], f64)>,
    ) {
        let first = node.first as usize;
        for &t in &self.bvh_items[first..first + node.count as usize] {
            let v = self.tets[t as usize].map(|i| self.points[i as usize]);
            if out.len() - base == n {
                let lo = v[0].min(v[1]).min(v[2]).min(v[3]);
                let hi = v[0].max(v[1]).max(v[2]).max(v[3]);
                let bound = (lo - p).max(p - hi).max(DVec3::ZERO).length();
                if bound > out[out.len() - 1].2 + slack {
                    continue;
                }
            }
            let inv = &self.frames[t as usize].inv;
            // Same inverse as `closest_point_in_tet` computes, so the same answer bit for bit.
            let (q, b) = closest_point_in_tet_with(p, v, inv.is_finite().then_some(inv));
            insert_nearest(out, base, n, (t, b, p.distance(q)));
        }
    }

    fn cell_coord(&self, x: f64, axis: usize) -> u32 {
        let f = ((x - self.lo[axis]) * self.inv_cell[axis]).floor();
        // Saturating cast then clamp: monotone in x, so a tet's box and any point inside it
        // always agree on the cells (this is what makes the grid exact).
        (f.max(0.0) as u32).min(self.dims[axis] - 1)
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
        self.lo = lo;
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
            self.for_each_registration(&grown, sample(), |_, _| registrations += 1);
            if registrations as f64 > budget {
                break;
            }
            dims = candidate;
            along = (along * 1.25).ceil();
        }
        self.set_dims(dims);
        let mut pairs = Vec::new();
        self.for_each_registration(&grown, 0..grown.len(), |t, cell| pairs.push((cell, t)));
        if u32::try_from(pairs.len()).is_err() {
            // Only for billions of tets: one cell keeps the offsets within u32.
            self.set_dims([1, 1, 1]);
            pairs.clear();
            self.for_each_registration(&grown, 0..grown.len(), |t, cell| pairs.push((cell, t)));
        }
        // Counting sort by cell; pairs come in ascending tet order, so every cell's list is
        // sorted and queries need no sort.
        let cells = self.dims.iter().map(|&d| d as usize).product::<usize>();
        let mut start = vec![0u32; cells + 1];
        for &(cell, _) in &pairs {
            start[cell + 1] += 1;
        }
        for c in 0..cells {
            start[c + 1] += start[c];
        }
        let mut fill = start.clone();
        let mut items = vec![0u32; pairs.len()];
        for &(cell, t) in &pairs {
            items[fill[cell] as usize] = t;
            fill[cell] += 1;
        }
        self.cell_start = start;
        self.cell_items = items;
    }

    fn set_dims(&mut self, dims: [u32; 3]) {
        let extent = self.hi - self.lo;
        self.dims = dims;
        self.inv_cell = DVec3::new(
            cell_inverse(dims[0], extent.x),
            cell_inverse(dims[1], extent.y),
            cell_inverse(dims[2], extent.z),
        );
    }

    /// Calls `f(tet, cell)` for every cell a tet's eps-region may reach: the cells of its grown
    /// box, minus those lying wholly beyond one of its face planes (by more than `BUILD_EPS`).
    /// The plane test is what keeps thin tets out of most cells of their box.
    fn for_each_registration(
        &self,
        grown: &[Option<(DVec3, DVec3)>],
        tets: impl Iterator<Item = usize>,
        mut f: impl FnMut(u32, usize),
    ) {
        let cell = DVec3::new(
            1.0 / self.inv_cell.x,
            1.0 / self.inv_cell.y,
            1.0 / self.inv_cell.z,
        );
        // Half a cell, grown so rounding in `cell_of` never puts a point outside its cell's box.
        let half = cell * (0.5 + 1e-9);
        for t in tets {
            let Some((lo, hi)) = grown[t] else { continue };
            let frame = &self.frames[t];
            let rows = [frame.inv.row(0), frame.inv.row(1), frame.inv.row(2)];
            // |grad λ_i| · half: how much λ_i can rise from a cell's centre to its corners.
            let reach = [
                (rows[0] + rows[1] + rows[2]).abs().dot(half),
                rows[0].abs().dot(half),
                rows[1].abs().dot(half),
                rows[2].abs().dot(half),
            ];
            let a = self.cell_of(lo);
            let b = self.cell_of(hi);
            // λ is affine: step it along x from each row's first centre instead of recomputing
            // it per cell (the drift is ~1e-15, far inside the BUILD_EPS − FAST_EPS slack).
            let dx = frame.inv * DVec3::new(cell.x, 0.0, 0.0);
            let step = [-(dx.x + dx.y + dx.z), dx.x, dx.y, dx.z];
            for z in a[2]..=b[2] {
                for y in a[1]..=b[1] {
                    let centre = self.lo
                        + DVec3::new(a[0] as f64 + 0.5, y as f64 + 0.5, z as f64 + 0.5) * cell;
                    let mut l = bary(frame, centre);
                    let row = self.linear([a[0], y, z]);
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

    fn build_bvh(&mut self, boxes: &[(DVec3, DVec3)]) {
        if boxes.is_empty() {
            return;
        }
        let centres: Vec<DVec3> = boxes.iter().map(|(lo, hi)| (*lo + *hi) * 0.5).collect();
        let mut items: Vec<u32> = (0..boxes.len() as u32).collect();
        let mut nodes = vec![Node {
            lo: DVec3::ZERO,
            hi: DVec3::ZERO,
            first: 0,
            count: 0,
        }];
        // (node, start, end) ranges of `items` still to split.
        let mut todo = vec![(0usize, 0usize, items.len())];
        while let Some((node, start, end)) = todo.pop() {
            let slice = &mut items[start..end];
            let (lo, hi) = slice
                .iter()
                .map(|&t| boxes[t as usize])
                .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
                .unwrap_or((DVec3::ZERO, DVec3::ZERO));
            nodes[node].lo = lo;
            nodes[node].hi = hi;
            if slice.len() <= LEAF_SIZE {
                nodes[node].first = start as u32;
                nodes[node].count = slice.len() as u32;
                continue;
            }
            let (clo, chi) = slice
                .iter()
                .map(|&t| centres[t as usize])
                .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |a, c| {
                    (a.0.min(c), a.1.max(c))
                });
            let axis = (chi - clo).max_position();
            let mid = slice.len() / 2;
            slice.select_nth_unstable_by(mid, |&a, &b| {
                centres[a as usize][axis]
                    .total_cmp(&centres[b as usize][axis])
                    .then(a.cmp(&b))
            });
            let left = nodes.len();
            nodes[node].first = left as u32;
            nodes[node].count = 0;
            let empty = nodes[node];
            nodes.push(empty);
            nodes.push(empty);
            todo.push((left, start, start + mid));
            todo.push((left + 1, start + mid, end));
        }
        self.nodes = nodes;
        self.bvh_items = items;
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

/// A lower bound of the distance from `p` to the non-flat tet with corners `c`: the largest
/// distance of `p` beyond one of its face planes (on the side away from the opposite corner).
/// 0 for a point inside.
fn plane_lower_bound(c: [DVec3; 4], p: DVec3) -> f64 {
    const FACES: [[usize; 3]; 4] = [[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]];
    // The largest squared distance beyond a face plane, with one square root at the end.
    let mut lb2 = 0.0f64;
    for (opposite, [i, j, k]) in FACES.into_iter().enumerate() {
        let n = (c[j] - c[i]).cross(c[k] - c[i]);
        let beyond = n.dot(p - c[i]);
        if beyond * n.dot(c[opposite] - c[i]) < 0.0 {
            lb2 = lb2.max(beyond * beyond / n.length_squared());
        }
    }
    let lb = lb2.sqrt();
    if lb.is_finite() {
        lb
    } else {
        0.0
    }
}

#[inline]
fn box_distance(p: DVec3, node: &Node) -> f64 {
    (node.lo - p).max(p - node.hi).max(DVec3::ZERO).length()
}

/// Keeps `out[base..]` the best `n` entries by (distance, tet), sorted.
fn insert_nearest(
    out: &mut Vec<(u32, [f64; 4], f64)>,
    base: usize,
    n: usize,
    item: (u32, [f64; 4], f64),
) {
    let before =
        |a: &(u32, [f64; 4], f64), b: &(u32, [f64; 4], f64)| a.2 < b.2 || (a.2 == b.2 && a.0 < b.0);
    let len = out.len() - base;
    if len == n {
        if !before(&item, &out[out.len() - 1]) {
            return;
        }
        out.pop();
    }
    let mut i = out.len();
    out.push(item);
    while i > base && before(&item, &out[i - 1]) {
        out[i] = out[i - 1];
        i -= 1;
    }
    out[i] = item;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tets::{closest_point_in_tet, generate_tets, TetConfig};
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngSeed};

    fn lcg_points(n: usize, seed: u64) -> Vec<DVec3> {
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let mut next = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        (0..n)
            .map(|_| DVec3::new(next(), next() * 0.6, next() * 0.3))
            .collect()
    }

    fn index(n: usize, seed: u64, cfg: &TetConfig) -> TetIndex {
        let pts = lcg_points(n, seed);
        let tets = generate_tets(&pts, cfg);
        TetIndex::new(pts, tets).unwrap()
    }

    fn brute_query(ix: &TetIndex, p: DVec3, eps: f64) -> Vec<(u32, [f64; 4])> {
        (0..ix.num_tets())
            .filter_map(|t| {
                let b = ix.barycentric(t, p);
                b.iter().all(|&x| x >= -eps).then_some((t as u32, b))
            })
            .collect()
    }

    fn brute_nearest(ix: &TetIndex, p: DVec3, n: usize) -> Vec<(u32, f64)> {
        let mut all: Vec<(u32, f64)> = ix
            .tets()
            .iter()
            .enumerate()
            .map(|(t, tet)| {
                let (q, _) = closest_point_in_tet(p, tet.map(|i| ix.points()[i as usize]));
                (t as u32, p.distance(q))
            })
            .collect();
        all.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        all.truncate(n);
        all
    }

    fn config(cases: u32, seed: u64) -> Config {
        Config {
            cases,
            rng_seed: RngSeed::Fixed(seed),
            failure_persistence: None,
            ..Config::default()
        }
    }

    #[test]
    fn single_tet_contains_its_centroid_and_vertices_but_not_outside_points() {
        let pts = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        let ix = TetIndex::new(pts, vec![[0, 1, 2, 3]]).unwrap();
        let mut out = Vec::new();
        ix.query(DVec3::splat(0.25), 1e-9, &mut out);
        assert_eq!(out.len(), 1);
        assert!(out[0].1.iter().all(|&b| (b - 0.25).abs() < 1e-15));
        for v in [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z] {
            out.clear();
            ix.query(v, 1e-9, &mut out);
            assert_eq!(out.len(), 1, "{v}");
        }
        // Beyond the box by 5e-8 but within eps = 1e-7: found (the grid's box has a margin).
        out.clear();
        ix.query(DVec3::new(1.0 + 5e-8, 0.0, 0.0), 1e-7, &mut out);
        assert_eq!(out.len(), 1);
        out.clear();
        ix.query(DVec3::new(1.0 + 5e-8, 0.0, 0.0), 1e-9, &mut out);
        ix.query(DVec3::splat(0.4), 1e-9, &mut out);
        ix.query(DVec3::new(-0.1, 0.2, 0.2), 1e-9, &mut out);
        ix.query(DVec3::splat(5.0), 1e-9, &mut out);
        ix.query(DVec3::NAN, 1e-9, &mut out);
        assert!(out.is_empty());
    }

    #[test]
    fn bad_input_is_an_input_error() {
        let pts = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        assert!(matches!(
            TetIndex::new(pts.clone(), vec![[0, 1, 2, 4]]),
            Err(LgiError::Input(_))
        ));
        let mut bad = pts;
        bad[2] = DVec3::NAN;
        assert!(matches!(
            TetIndex::new(bad, vec![[0, 1, 2, 3]]),
            Err(LgiError::Input(_))
        ));
    }

    #[test]
    fn empty_and_flat_tets_contain_nothing_but_flat_ones_are_still_nearest() {
        let ix = TetIndex::new(vec![DVec3::ZERO], vec![]).unwrap();
        let mut out = Vec::new();
        ix.query(DVec3::ZERO, 1e-9, &mut out);
        assert!(out.is_empty());
        let mut near = Vec::new();
        ix.nearest(DVec3::ZERO, 3, &mut near);
        assert!(near.is_empty());

        let flat = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(0.5, 0.5, 0.0)];
        let ix = TetIndex::new(flat, vec![[0, 1, 2, 3]]).unwrap();
        ix.query(DVec3::new(0.2, 0.2, 0.0), 1e-9, &mut out);
        ix.query(DVec3::new(0.2, 0.2, 0.0), 1.0, &mut out);
        assert!(out.is_empty());
        ix.nearest(DVec3::new(0.2, 0.2, 1.0), 3, &mut near);
        assert_eq!(near.len(), 1);
        assert!((near[0].2 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn query_and_nearest_append_without_touching_existing_entries() {
        let ix = index(40, 5, &TetConfig::default());
        let p = ix.points()[3];
        let mut out = vec![(u32::MAX, [9.0; 4])];
        ix.query(p, 1e-9, &mut out);
        assert_eq!(out[0].0, u32::MAX);
        assert_eq!(out[1..], brute_query(&ix, p, 1e-9)[..]);
        let mut near = vec![(u32::MAX, [9.0; 4], -1.0)];
        ix.nearest(DVec3::splat(3.0), 5, &mut near);
        assert_eq!(near[0].0, u32::MAX);
        let got: Vec<(u32, f64)> = near[1..].iter().map(|e| (e.0, e.2)).collect();
        assert_eq!(got, brute_nearest(&ix, DVec3::splat(3.0), 5));
    }

    #[test]
    fn large_eps_falls_back_to_scanning_and_still_matches_brute_force() {
        let ix = index(30, 9, &TetConfig::default());
        let mut out = Vec::new();
        for p in [DVec3::new(1.05, 0.3, 0.1), DVec3::new(0.5, 0.3, 0.15)] {
            out.clear();
            ix.query(p, 0.1, &mut out);
            assert_eq!(out, brute_query(&ix, p, 0.1));
        }
    }

    /// A random point of the kind named by `kind` on tet `t`: 0 vertex, 1 edge, 2 face, 3 interior,
    /// 5 just outside a vertex (kind 4, a point near the cloud, is made by the caller).
    fn special_point(ix: &TetIndex, t: usize, kind: u8, w: [f64; 4]) -> DVec3 {
        let v = ix.tets()[t].map(|i| ix.points()[i as usize]);
        let mut w = w;
        match kind {
            0 => w = [1.0, 0.0, 0.0, 0.0],
            // Just beyond a vertex, by less than eps = 1e-7 in every barycentric coordinate.
            5 => w = [1.0 + 9e-8, -3e-8, -3e-8, -3e-8],
            1 => {
                w[2] = 0.0;
                w[3] = 0.0;
            }
            2 => w[3] = 0.0,
            _ => {}
        }
        let s: f64 = w.iter().sum();
        // Rotate which vertices get the zero weights so every vertex, edge and face is hit.
        let r = (w[0] * 1e6) as usize % 4;
        (0..4).map(|i| v[(i + r) % 4] * (w[i] / s)).sum()
    }

    proptest! {
        #![proptest_config(config(128, 0x9e1d_0001))]

        #[test]
        fn query_matches_brute_force_on_random_and_special_points(
            n in 5usize..80,
            seed in any::<u64>(),
            k in 3usize..12,
            samples in prop::collection::vec(
                (any::<prop::sample::Index>(), 0u8..6, [0.01..1.0f64, 0.01..1.0, 0.01..1.0, 0.01..1.0],
                 (-0.2..1.2f64, -0.2..0.8f64, -0.2..0.5f64)),
                20..60),
        ) {
            let cfg = TetConfig { neighbours: k, ..TetConfig::default() };
            let ix = index(n, seed, &cfg);
            prop_assume!(ix.num_tets() > 0);
            let mut out = Vec::new();
            for (t, kind, w, (x, y, z)) in samples {
                let p = if kind == 4 {
                    DVec3::new(x, y, z)
                } else {
                    special_point(&ix, t.index(ix.num_tets()), kind, w)
                };
                for eps in [0.0, 1e-9, 1e-7] {
                    out.clear();
                    ix.query(p, eps, &mut out);
                    prop_assert_eq!(&out, &brute_query(&ix, p, eps));
                }
                if kind != 4 {
                    // A point built on a tet is found in that tet (up to rounding).
                    out.clear();
                    ix.query(p, if kind == 5 { 1e-7 } else { 1e-9 }, &mut out);
                    prop_assert!(!out.is_empty());
                }
            }
        }

        #[test]
        fn nearest_matches_brute_force_closest_points(
            n in 5usize..60,
            seed in any::<u64>(),
            count in 1usize..12,
            queries in prop::collection::vec((-1.0..2.0f64, -1.0..1.6f64, -1.0..1.3f64), 10),
        ) {
            let ix = index(n, seed, &TetConfig::default());
            let mut out = Vec::new();
            for (x, y, z) in queries {
                let p = DVec3::new(x, y, z);
                out.clear();
                ix.nearest(p, count, &mut out);
                let got: Vec<(u32, f64)> = out.iter().map(|e| (e.0, e.2)).collect();
                prop_assert_eq!(got, brute_nearest(&ix, p, count));
                for (t, b, d) in &out {
                    let v = ix.tets()[*t as usize].map(|i| ix.points()[i as usize]);
                    let q: DVec3 = (0..4).map(|i| v[i] * b[i]).sum();
                    prop_assert!((p.distance(q) - d).abs() < 1e-9);
                    prop_assert!(b.iter().all(|&x| x >= 0.0));
                }
            }
        }
    }

    #[test]
    fn index_is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<TetIndex>();
    }

    #[test]
    fn nearest_around_returns_exactly_the_tets_of_the_nearest_points_with_exact_distances() {
        let cfg = TetConfig::default();
        let ix = index(60, 11, &cfg);
        let pts = ix.points().to_vec();
        for (qi, q) in [
            DVec3::new(2.0, -1.0, 0.5),
            DVec3::new(0.3, 0.2, 0.1),
            DVec3::splat(-3.0),
        ]
        .into_iter()
        .enumerate()
        {
            for k in [1usize, 3] {
                let mut out = Vec::new();
                ix.nearest_around(q, k, &mut out);
                // Brute force: the k nearest points (ties by index) and every tet touching one.
                let mut order: Vec<usize> = (0..pts.len()).collect();
                order.sort_by(|&a, &b| {
                    pts[a]
                        .distance_squared(q)
                        .total_cmp(&pts[b].distance_squared(q))
                        .then(a.cmp(&b))
                });
                let near = &order[..k];
                let mut want: Vec<u32> = (0..ix.num_tets() as u32)
                    .filter(|&t| {
                        ix.tets()[t as usize]
                            .iter()
                            .any(|v| near.contains(&(*v as usize)))
                    })
                    .collect();
                want.sort_unstable();
                let mut got: Vec<u32> = out.iter().map(|c| c.0).collect();
                got.sort_unstable();
                assert_eq!(got, want, "query {qi}, k {k}");
                for w in out.windows(2) {
                    assert!(w[0].2 <= w[1].2);
                }
                for &(t, _, d) in &out {
                    let corners = ix.tets()[t as usize].map(|i| pts[i as usize]);
                    let (c, _) = crate::tets::closest_point_in_tet(q, corners);
                    assert!((c.distance(q) - d).abs() <= 1e-12 * (1.0 + d));
                }
            }
        }
    }

    /// `project_around(q, n)` equals projecting every tet around the nearest point, dropping
    /// closest points at a vertex and keeping the n nearest.
    fn projection_equals_unpruned(ix: &TetIndex, q: DVec3, n: usize) -> Result<(), TestCaseError> {
        let (mut bounds, mut got, mut all) = (Vec::new(), Vec::new(), Vec::new());
        ix.project_around(q, n, &mut bounds, &mut got);
        ix.nearest_around(q, 1, &mut all);
        all.retain(|c| c.1.iter().all(|&b| b < 1.0 - 1e-12));
        all.truncate(n);
        prop_assert_eq!(&got, &all);
        Ok(())
    }

    proptest! {
        #![proptest_config(config(96, 0x9e1d_0007))]

        /// The pruned projection gives bit for bit what projecting every incident tet, dropping
        /// vertex closest points and keeping the n nearest gives.
        #[test]
        fn project_around_equals_the_unpruned_projection_filtered_and_truncated(
            npts in 5usize..80,
            seed in any::<u64>(),
            n in 1usize..12,
            samples in prop::collection::vec(
                (-1.5f64..1.5, -1.5f64..1.5, -1.5f64..1.5), 1..16),
        ) {
            let ix = index(npts, seed, &TetConfig::default());
            for (x, y, z) in samples {
                // Far and near points, outside and inside the cloud.
                for q in [DVec3::new(x, y, z), DVec3::new(x, y, z) * 3.0] {
                    projection_equals_unpruned(&ix, q, n)?;
                }
            }
        }

        /// The same on arbitrary tets over a cloud with a coplanar part: flat tets (singular
        /// frames, bound 0), tets with a repeated corner and sliver tets go through the inline
        /// corners and the bound like any other.
        #[test]
        fn project_around_equals_the_unpruned_projection_with_flat_and_degenerate_tets(
            npts in 5usize..40,
            seed in any::<u64>(),
            picks in prop::collection::vec(any::<[u16; 4]>(), 1..120),
            n in 1usize..10,
            samples in prop::collection::vec(
                (-1.5f64..1.5, -1.5f64..1.5, -1.5f64..1.5), 1..10),
        ) {
            let mut pts = lcg_points(npts, seed);
            // A third of the points on the plane z = 0: tets among them are flat.
            for p in pts.iter_mut().step_by(3) {
                p.z = 0.0;
            }
            let tets: Vec<Tet> = picks
                .iter()
                .map(|c| c.map(|i| u32::from(i) % npts as u32))
                .collect();
            let ix = TetIndex::new(pts, tets).unwrap();
            for (x, y, z) in samples {
                for q in [DVec3::new(x, y, z), DVec3::new(x, y, 0.0), DVec3::new(x, y, z) * 3.0] {
                    projection_equals_unpruned(&ix, q, n)?;
                }
            }
        }
    }
}
