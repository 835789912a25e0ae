//! Natural-neighbour (Sibson) weights of query points (mesh vertices) w.r.t. sites (bundles) in UV
//! space: the C0 partition of unity that sews the bundles' local geometries. Extrapolates from the
//! convex hull boundary and never sees across a hole (mouth, eyes) given as barrier segments.

use crate::error::{LgiError, Result};
use crate::sparse::SparseWeights;
use glam::DVec2;
use rayon::prelude::*;
use spade::handles::FixedVertexHandle;
use spade::{DelaunayTriangulation, HasPosition, NaturalNeighbor, Point2, Triangulation};

/// A 2D segment that weights must not see across (a hole boundary edge in UV, e.g. the mouth
/// slit or an eye).
pub type Barrier = [DVec2; 2];

/// Weights below this (after normalisation) are dropped: they carry no geometry and would only
/// densify the matrix.
const DROP_BELOW: f64 = 1e-14;

/// Largest acceptable |Σ w_i s_i - q| in the internal unit frame before spade's weights are
/// distrusted (they are normally exact to ~1e-15).
const RESIDUAL_TOL: f64 = 1e-11;

/// Query coordinates are clamped to ±FAR in the internal unit frame (where every site has
/// |coordinates| < 1): such queries are far outside the hull, clamping barely moves their
/// nearest hull point, and squared distances of huge coordinates would lose all precision.
const FAR: f64 = 1e6;

/// Spade vertex: a site position in the internal frame and its index in the input.
#[derive(Debug, Clone, Copy)]
struct Site {
    pos: Point2<f64>,
    index: u32,
}

impl HasPosition for Site {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.pos
    }
}

/// Natural-neighbour weights of a fixed set of sites, with optional barriers.
///
/// Holds the Delaunay triangulation of the sites (in an internal frame scaled by a power of two,
/// which is exact, so that coordinates are O(1) whatever the input units). `Send + Sync`: each
/// rayon worker builds its own spade `NaturalNeighbor` (which is not `Sync`).
///
/// Rules, per query point q:
/// - inside the sites' convex hull: Sibson weights (area stolen from each natural neighbour's
///   Voronoi cell by q's cell);
/// - outside: the weights of the closest point of the hull boundary, i.e. linear interpolation
///   of the two endpoints of the nearest hull edge (Sibson weights on a hull edge are exactly
///   that, so the rule is continuous across the hull). Inside but on (or within rounding of) a
///   hull edge next to a sliver triangle, where spade's weights lose all precision (detected as
///   `Σ w_i s_i != q`), the same projection is used;
/// - barriers: a site whose straight segment from q crosses a barrier gets weight 0 and the
///   others are renormalised. If every natural neighbour is hidden, q takes weight 1 on the
///   nearest visible site (ties: lowest index); if no site at all is visible (q enclosed by
///   barriers), the barrier-free weights are kept;
/// - non-finite queries (e.g. vertices without UVs, see [`vertex_charts`](crate::uvspace::vertex_charts)) get an empty row.
///
/// Weights below 1e-14 are dropped and rows renormalised (sum 1 within 1e-12, all > 0).
///
/// Known limitation: hiding a site is a discontinuous event; a query whose sight line to a site
/// sweeps past a barrier's end sees that site's weight jump (inherent to visibility weights).
#[derive(Debug)]
pub struct SibsonWeights {
    tri: DelaunayTriangulation<Site>,
    /// Sites in the internal frame, by input index.
    sites: Vec<DVec2>,
    /// Input → internal frame factor (a power of two).
    scale: f64,
    /// Convex hull vertices (site indices) in cyclic order.
    hull: Vec<u32>,
    barriers: BarrierGrid,
}

/// Per-worker scratch space for [`SibsonWeights::row_into`].
struct Scratch<'a> {
    nn: NaturalNeighbor<'a, DelaunayTriangulation<Site>>,
    spade_out: Vec<(FixedVertexHandle, f64)>,
    unfiltered: Vec<(u32, f64)>,
    /// The last row before barriers and the drop of tiny weights.
    support: Vec<(u32, f64)>,
    visit: VisitStamps,
}

impl SibsonWeights {
    /// Triangulates the sites (bundle UV positions, B of them) and indexes the barriers.
    ///
    /// Errors (`LgiError::Input`): fewer than 3 sites, a non-finite site or barrier coordinate,
    /// two coinciding sites (both indices named), all sites on one line. Zero-length barriers
    /// are ignored.
    pub fn new(sites: &[DVec2], barriers: &[Barrier]) -> Result<Self> {
        if sites.len() < 3 {
            return Err(LgiError::Input(format!(
                "natural-neighbour weights need at least 3 sites, got {}",
                sites.len()
            )));
        }
        if sites.len() > u32::MAX as usize {
            return Err(LgiError::Input(format!("too many sites: {}", sites.len())));
        }
        if let Some(i) = sites.iter().position(|p| !p.is_finite()) {
            return Err(LgiError::Input(format!(
                "site {i} has a non-finite coordinate {}",
                crate::text::uv(sites[i])
            )));
        }
        if let Some(k) = barriers
            .iter()
            .position(|b| !(b[0].is_finite() && b[1].is_finite()))
        {
            return Err(LgiError::Input(format!(
                "barrier {k} has a non-finite coordinate {} - {}",
                crate::text::uv(barriers[k][0]),
                crate::text::uv(barriers[k][1])
            )));
        }
        let max_abs = sites
            .iter()
            .fold(0.0_f64, |m, p| m.max(p.x.abs()).max(p.y.abs()));
        let scale = frame_scale(max_abs);
        let local: Vec<DVec2> = sites
            .iter()
            .map(|&p| {
                // Spade rejects |coordinates| below 2^-142 (predicate underflow); relative to a
                // unit extent such values are zero anyway. `+ 0.0` folds -0 into +0 so that
                // the duplicate check sees them as equal.
                let m = spade::mitigate_underflow(Point2::new(p.x * scale, p.y * scale));
                DVec2::new(m.x + 0.0, m.y + 0.0)
            })
            .collect();
        check_duplicates(&local)?;
        let vertices: Vec<Site> = local
            .iter()
            .enumerate()
            .map(|(i, p)| Site {
                pos: Point2::new(p.x, p.y),
                index: i as u32,
            })
            .collect();
        let tri = DelaunayTriangulation::<Site>::bulk_load(vertices)
            .map_err(|e| LgiError::Input(format!("cannot triangulate the sites: {e:?}")))?;
        if tri.num_vertices() != sites.len() {
            return Err(LgiError::Input(format!(
                "the triangulation kept {} of {} sites (coinciding sites?)",
                tri.num_vertices(),
                sites.len()
            )));
        }
        if tri.all_vertices_on_line() || tri.num_inner_faces() == 0 {
            return Err(LgiError::Input(format!(
                "all {} sites lie on one line: natural-neighbour weights need a 2D spread",
                sites.len()
            )));
        }
        let hull: Vec<u32> = tri.convex_hull().map(|e| e.from().data().index).collect();
        let scaled: Vec<Barrier> = barriers
            .iter()
            .filter(|b| b[0] != b[1])
            .map(|b| [b[0] * scale, b[1] * scale])
            .collect();
        Ok(SibsonWeights {
            tri,
            sites: local,
            scale,
            hull,
            barriers: BarrierGrid::new(scaled),
        })
    }

    /// Number of sites (columns).
    pub fn num_sites(&self) -> usize {
        self.sites.len()
    }

    /// Weights of every query point (V rows, B columns), computed in parallel (rayon).
    pub fn weights(&self, queries: &[DVec2]) -> SparseWeights {
        self.rows(queries, false).0
    }

    /// [`weights`](Self::weights), and each row's columns before barriers hide any and tiny
    /// weights are dropped (the natural neighbours, or the nearest hull edge's ends; weights
    /// as they were), sorted: every site whose removal could change the row.
    pub fn weights_and_support(&self, queries: &[DVec2]) -> (SparseWeights, SparseWeights) {
        self.rows(queries, true)
    }

    fn rows(&self, queries: &[DVec2], with_support: bool) -> (SparseWeights, SparseWeights) {
        // Up to 256 queries a task, fewer for a few hundred (a missing set's rows) so that
        // every thread gets some.
        let chunk = (queries.len() / (4 * rayon::current_num_threads())).clamp(16, 256);
        type Part = (Vec<u32>, Vec<u32>, Vec<f64>);
        let chunks: Vec<(Part, Part)> = queries
            .par_chunks(chunk)
            .map_init(
                || self.scratch(),
                |scratch, chunk| {
                    let mut main: Part = (
                        Vec::with_capacity(chunk.len()),
                        Vec::with_capacity(chunk.len() * 6),
                        Vec::with_capacity(chunk.len() * 6),
                    );
                    let mut support: Part = Default::default();
                    let mut row = Vec::new();
                    for &q in chunk {
                        self.row_into(q, scratch, &mut row);
                        main.0.push(row.len() as u32);
                        for &(c, w) in &row {
                            main.1.push(c);
                            main.2.push(w);
                        }
                        if with_support {
                            let s = &mut scratch.support;
                            s.sort_unstable_by_key(|&(c, _)| c);
                            support.0.push(s.len() as u32);
                            for &(c, w) in s.iter() {
                                support.1.push(c);
                                support.2.push(w);
                            }
                        }
                    }
                    (main, support)
                },
            )
            .collect();
        let assemble = |parts: &mut dyn Iterator<Item = Part>, rows: usize| {
            let mut out = SparseWeights {
                row_start: Vec::with_capacity(rows + 1),
                cols: Vec::new(),
                vals: Vec::new(),
                num_cols: self.sites.len(),
            };
            out.row_start.push(0);
            for (lens, cols, vals) in parts {
                let mut at = out.cols.len() as u32;
                for l in lens {
                    at += l;
                    out.row_start.push(at);
                }
                out.cols.extend(cols);
                out.vals.extend(vals);
            }
            out
        };
        let (main, support): (Vec<Part>, Vec<Part>) = chunks.into_iter().unzip();
        let n = queries.len();
        let support = match with_support {
            true => assemble(&mut support.into_iter(), n),
            false => SparseWeights::empty(self.sites.len()),
        };
        (assemble(&mut main.into_iter(), n), support)
    }

    /// Delaunay neighbours of each site (sorted), excluding pairs whose connecting segment
    /// crosses a barrier.
    pub fn neighbours(&self) -> Vec<Vec<u32>> {
        let mut visit = VisitStamps::new(self.barriers.len());
        let mut out = vec![Vec::new(); self.sites.len()];
        for e in self.tri.undirected_edges() {
            let [a, b] = e.vertices().map(|v| v.data().index);
            let (pa, pb) = (self.sites[a as usize], self.sites[b as usize]);
            if !self.barriers.blocks(pa, pb, &mut visit) {
                out[a as usize].push(b);
                out[b as usize].push(a);
            }
        }
        for n in &mut out {
            n.sort_unstable();
        }
        out
    }

    fn scratch(&self) -> Scratch<'_> {
        Scratch {
            nn: self.tri.natural_neighbor(),
            spade_out: Vec::new(),
            unfiltered: Vec::new(),
            support: Vec::new(),
            visit: VisitStamps::new(self.barriers.len()),
        }
    }

    /// Input coordinates → internal frame; `None` for non-finite queries.
    fn to_local(&self, q: DVec2) -> Option<DVec2> {
        if !q.is_finite() {
            return None;
        }
        // Clamp in the input frame: `q * scale` itself may overflow. `FAR / scale` is finite
        // because the scale is at least 2^-1000.
        let lim = FAR / self.scale;
        let l = q.clamp(DVec2::splat(-lim), DVec2::splat(lim)) * self.scale;
        let p = spade::mitigate_underflow(Point2::new(l.x, l.y));
        Some(DVec2::new(p.x, p.y))
    }

    /// The weights of one query, sorted by column, into `out`.
    fn row_into(&self, q: DVec2, s: &mut Scratch<'_>, out: &mut Vec<(u32, f64)>) {
        out.clear();
        s.support.clear();
        let Some(q) = self.to_local(q) else {
            return;
        };
        s.nn.get_weights(Point2::new(q.x, q.y), &mut s.spade_out);
        let spade_ok = !s.spade_out.is_empty()
            && s.spade_out.iter().all(|&(_, w)| w.is_finite())
            && s.spade_out.iter().map(|&(_, w)| w.max(0.0)).sum::<f64>() > 0.0;
        if spade_ok {
            out.extend(
                s.spade_out
                    .iter()
                    .map(|&(h, w)| (self.tri.vertex(h).data().index, w.max(0.0))),
            );
            normalise(out);
            // Sibson weights reproduce the position exactly. Spade's circumcentres lose all
            // precision when q is (nearly) on the hull next to a sliver triangle (near-collinear
            // hull sites); there the hull projection is the right answer, so keep whichever
            // reproduces q better.
            let residual = self.residual(q, out);
            if residual > RESIDUAL_TOL {
                s.unfiltered.clear();
                self.hull_weights(q, &mut s.unfiltered);
                if self.residual(q, &s.unfiltered) < residual {
                    out.clear();
                    out.extend_from_slice(&s.unfiltered);
                }
            }
        } else {
            // Outside the hull (spade gives nothing), or so close to a hull edge that spade's
            // circumcentres overflowed: either way the nearest hull point is the answer.
            self.hull_weights(q, out);
        }
        normalise(out);
        s.support.extend_from_slice(out);
        if !self.barriers.is_empty() {
            self.hide_behind_barriers(q, s, out);
        }
        normalise(out);
        out.retain(|&(_, w)| w >= DROP_BELOW);
        normalise(out);
        out.sort_unstable_by_key(|&(c, _)| c);
    }

    /// |Σ w_i s_i - q|: how far the weights are from reproducing q (0 for exact Sibson weights).
    fn residual(&self, q: DVec2, row: &[(u32, f64)]) -> f64 {
        let p: DVec2 = row.iter().map(|&(i, w)| self.sites[i as usize] * w).sum();
        (p - q).length()
    }

    /// Linear interpolation of the endpoints of the hull edge nearest to `q` (the Sibson weights
    /// of q's closest point on the hull boundary).
    fn hull_weights(&self, q: DVec2, out: &mut Vec<(u32, f64)>) {
        out.clear();
        let n = self.hull.len();
        let mut best = (f64::INFINITY, 0u32, 0u32, 0.0f64);
        for k in 0..n {
            let (ia, ib) = (self.hull[k], self.hull[(k + 1) % n]);
            let (a, b) = (self.sites[ia as usize], self.sites[ib as usize]);
            let ab = b - a;
            let t = ((q - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
            let d2 = (a + ab * t - q).length_squared();
            if d2 < best.0 {
                best = (d2, ia, ib, t);
            }
        }
        let (_, ia, ib, t) = best;
        out.push((ia, 1.0 - t));
        out.push((ib, t));
    }

    /// Zeroes the weights of sites hidden from `q` by a barrier; see the type's doc for the
    /// fallbacks when nothing is left.
    fn hide_behind_barriers(&self, q: DVec2, s: &mut Scratch<'_>, out: &mut Vec<(u32, f64)>) {
        s.unfiltered.clear();
        s.unfiltered.extend_from_slice(out);
        let mut visible = false;
        for e in out.iter_mut() {
            if e.1 > 0.0
                && self
                    .barriers
                    .blocks(q, self.sites[e.0 as usize], &mut s.visit)
            {
                e.1 = 0.0;
            }
            visible |= e.1 > 0.0;
        }
        if visible {
            return;
        }
        // Every natural neighbour is hidden (q sits in a pocket of barriers): the nearest
        // visible site is the only information left that does not leak across a hole.
        let mut order: Vec<(f64, u32)> = self
            .sites
            .iter()
            .enumerate()
            .map(|(i, p)| ((*p - q).length_squared(), i as u32))
            .collect();
        order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        out.clear();
        match order.iter().find(|&&(_, i)| {
            !self
                .barriers
                .blocks(q, self.sites[i as usize], &mut s.visit)
        }) {
            Some(&(_, i)) => out.push((i, 1.0)),
            None => out.extend_from_slice(&s.unfiltered),
        }
    }
}

/// The power of two that brings the largest coordinate into [0.5, 1): exact scaling.
fn frame_scale(max_abs: f64) -> f64 {
    if max_abs == 0.0 || !max_abs.is_finite() {
        return 1.0;
    }
    let e = (max_abs.log2().floor() as i32 + 1).clamp(-1000, 1000);
    2f64.powi(-e)
}

/// Errors naming the first two coinciding sites (lowest indices).
fn check_duplicates(local: &[DVec2]) -> Result<()> {
    let mut order: Vec<u32> = (0..local.len() as u32).collect();
    let key = |i: u32| local[i as usize];
    order.sort_unstable_by(|&a, &b| {
        let (pa, pb) = (key(a), key(b));
        pa.x.total_cmp(&pb.x)
            .then(pa.y.total_cmp(&pb.y))
            .then(a.cmp(&b))
    });
    let dup = order
        .windows(2)
        .filter(|w| key(w[0]) == key(w[1]))
        .map(|w| (w[0], w[1]))
        .min();
    match dup {
        Some((i, j)) => Err(LgiError::Input(format!(
            "sites {i} and {j} coincide (at {}): natural-neighbour weights need distinct \
             sites; remove or merge one of them",
            crate::text::uv(local[i as usize])
        ))),
        None => Ok(()),
    }
}

/// Clamps negatives to zero and divides by the sum (no-op on an empty or all-zero row).
fn normalise(row: &mut [(u32, f64)]) {
    let sum: f64 = row.iter().map(|e| e.1.max(0.0)).sum();
    if sum > 0.0 && sum.is_finite() {
        for e in row.iter_mut() {
            e.1 = e.1.max(0.0) / sum;
        }
    }
}

/// Exact sign of the orientation of (a, b, c): > 0 counter-clockwise, < 0 clockwise, 0 collinear.
fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    let co = |p: DVec2| robust::Coord { x: p.x, y: p.y };
    robust::orient2d(co(a), co(b), co(c))
}

/// Whether `a`, known to be collinear with p and s, lies strictly between them.
fn strictly_between(p: DVec2, s: DVec2, a: DVec2) -> bool {
    // Along the dominant axis the comparison is exact for a collinear point.
    let (lo, hi, x) = if (s.x - p.x).abs() >= (s.y - p.y).abs() {
        (p.x.min(s.x), p.x.max(s.x), a.x)
    } else {
        (p.y.min(s.y), p.y.max(s.y), a.y)
    };
    lo < x && x < hi
}

/// Whether the closed barrier `[a, b]` meets the sight segment from `p` to `s` anywhere but at
/// `p` or `s` themselves.
///
/// Touching at p or s does not block: a query vertex on a hole's rim, or a site on it, sees
/// along the rim. A barrier endpoint strictly inside the sight segment blocks: otherwise a
/// sight line through the shared vertex of two barrier edges would slip through the polyline.
/// A barrier collinear with the sight line only blocks through such an endpoint: running along
/// a barrier is not crossing it.
fn segment_blocks(p: DVec2, s: DVec2, a: DVec2, b: DVec2) -> bool {
    let d1 = orient(p, s, a);
    let d2 = orient(p, s, b);
    if (d1 > 0.0 && d2 > 0.0) || (d1 < 0.0 && d2 < 0.0) {
        return false;
    }
    if d1 != 0.0 && d2 != 0.0 {
        let d3 = orient(a, b, p);
        let d4 = orient(a, b, s);
        return (d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0);
    }
    (d1 == 0.0 && strictly_between(p, s, a)) || (d2 == 0.0 && strictly_between(p, s, b))
}

/// Whether the closed boxes `(lo, hi)` `a` and `b` share no point (apart on some axis).
fn boxes_apart(a: (DVec2, DVec2), b: (DVec2, DVec2)) -> bool {
    a.1.cmplt(b.0).any() || a.0.cmpgt(b.1).any()
}

/// Per-worker "already tested" marks, so that a barrier spanning several grid cells is tested
/// once per sight segment.
struct VisitStamps {
    stamp: Vec<u32>,
    epoch: u32,
}

impl VisitStamps {
    fn new(n: usize) -> Self {
        VisitStamps {
            stamp: vec![0; n],
            epoch: 0,
        }
    }

    fn next_epoch(&mut self) {
        self.epoch = self.epoch.wrapping_add(1);
        if self.epoch == 0 {
            self.stamp.fill(0);
            self.epoch = 1;
        }
    }
}

/// Uniform grid of barrier segments (each listed in every cell its bounding box overlaps):
/// a sight segment only tests the barriers of the cells its bounding box overlaps.
#[derive(Debug, Default)]
struct BarrierGrid {
    segs: Vec<Barrier>,
    lo: DVec2,
    hi: DVec2,
    inv_cell: DVec2,
    nx: usize,
    ny: usize,
    cell_start: Vec<u32>,
    items: Vec<u32>,
}

impl BarrierGrid {
    fn new(segs: Vec<Barrier>) -> Self {
        if segs.is_empty() {
            return BarrierGrid::default();
        }
        let (lo, hi) = segs.iter().fold(
            (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY)),
            |(lo, hi), s| (lo.min(s[0]).min(s[1]), hi.max(s[0]).max(s[1])),
        );
        let ext = hi - lo;
        let n = segs.len() as f64;
        // About one cell per barrier, square cells; a degenerate (flat) box gets a strip.
        let cell = if ext.x > 0.0 && ext.y > 0.0 {
            (ext.x * ext.y / n).sqrt()
        } else {
            ext.max_element() / n
        };
        let dim = |e: f64| {
            if cell > 0.0 && e > 0.0 {
                ((e / cell).ceil() as usize).clamp(1, 1024)
            } else {
                1
            }
        };
        let (nx, ny) = (dim(ext.x), dim(ext.y));
        let inv = |e: f64, k: usize| if e > 0.0 { k as f64 / e } else { 0.0 };
        let mut grid = BarrierGrid {
            segs,
            lo,
            hi,
            inv_cell: DVec2::new(inv(ext.x, nx), inv(ext.y, ny)),
            nx,
            ny,
            cell_start: vec![0; nx * ny + 1],
            items: Vec::new(),
        };
        // Two passes (count, fill) build the cell lists in CSR form.
        let ranges: Vec<_> = grid
            .segs
            .iter()
            .map(|s| grid.cell_range(s[0].min(s[1]), s[0].max(s[1])))
            .collect();
        for &(i0, j0, i1, j1) in &ranges {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    grid.cell_start[j * nx + i + 1] += 1;
                }
            }
        }
        for c in 0..nx * ny {
            grid.cell_start[c + 1] += grid.cell_start[c];
        }
        let mut fill = grid.cell_start.clone();
        grid.items = vec![0; grid.cell_start[nx * ny] as usize];
        for (k, &(i0, j0, i1, j1)) in ranges.iter().enumerate() {
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let c = j * nx + i;
                    grid.items[fill[c] as usize] = k as u32;
                    fill[c] += 1;
                }
            }
        }
        grid
    }

    fn len(&self) -> usize {
        self.segs.len()
    }

    fn is_empty(&self) -> bool {
        self.segs.is_empty()
    }

    /// Cells (i0, j0, i1, j1) overlapped by the box [lo, hi]; monotone in the coordinates, so a
    /// barrier and a sight segment whose boxes overlap share a cell.
    fn cell_range(&self, lo: DVec2, hi: DVec2) -> (usize, usize, usize, usize) {
        // The casts truncate and saturate (negative and NaN to 0): `floor().max(0)` without
        // the libm call.
        let cx = |x: f64| (((x - self.lo.x) * self.inv_cell.x) as usize).min(self.nx - 1);
        let cy = |y: f64| (((y - self.lo.y) * self.inv_cell.y) as usize).min(self.ny - 1);
        (cx(lo.x), cy(lo.y), cx(hi.x), cy(hi.y))
    }

    /// Whether any barrier blocks the sight segment from `p` to `s` (see [`segment_blocks`]).
    fn blocks(&self, p: DVec2, s: DVec2, visit: &mut VisitStamps) -> bool {
        if self.segs.is_empty() {
            return false;
        }
        let (lo, hi) = (p.min(s), p.max(s));
        if boxes_apart((lo, hi), (self.lo, self.hi)) {
            return false;
        }
        visit.next_epoch();
        let (i0, j0, i1, j1) = self.cell_range(lo, hi);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let c = j * self.nx + i;
                let ids = &self.items[self.cell_start[c] as usize..self.cell_start[c + 1] as usize];
                for &k in ids {
                    let k = k as usize;
                    if visit.stamp[k] == visit.epoch {
                        continue;
                    }
                    visit.stamp[k] = visit.epoch;
                    let [a, b] = self.segs[k];
                    // Segments whose boxes are apart cannot meet: skips the exact predicates
                    // for most of the barriers a long sight segment's cells list.
                    if !boxes_apart((lo, hi), (a.min(b), a.max(b))) && segment_blocks(p, s, a, b) {
                        return true;
                    }
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests;
