//! Nearest tets and the projection of points outside every tet: a median-split box hierarchy
//! answers "the n tets nearest to this point" exactly, and the tets incident to the nearest cloud
//! point give the cheaper projection LGI uses for bundles that left their cloud.

use glam::DVec3;

use super::{Incident, TetIndex, FLAT};
use crate::prefetch::prefetch;
use crate::tets::closest_point_in_tet_with;

/// Tets per leaf of the nearest-tet hierarchy.
const LEAF_SIZE: usize = 4;
/// Fixed traversal stack: the median-split hierarchy is at most ~33 levels deep for 2³² tets.
const STACK: usize = 96;

/// How many candidates ahead the projection prefetches a frame.
const LOOKAHEAD: usize = 4;

/// A node of the nearest-tet hierarchy: the box of a range of `bvh_items`.
#[derive(Debug, Clone, Copy)]
pub(super) struct Node {
    lo: DVec3,
    hi: DVec3,
    /// Leaf: first position in `bvh_items`; inner: index of the left child (right = left + 1).
    first: u32,
    /// Leaf: number of tets (> 0); inner: 0.
    count: u32,
}

impl TetIndex {
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
                        .map(|inc| inc.tet())
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
        if !self.points.is_empty() {
            self.project_around_point(p, self.nearest_point(p), n, bounds, out);
        }
    }

    /// [`project_around`](Self::project_around) given the cloud point nearest to `p`
    /// (`v`, ties: lowest index), for a caller that has the point distances already.
    pub(crate) fn project_around_point(
        &self,
        p: DVec3,
        v: usize,
        n: usize,
        bounds: &mut Vec<(f64, u32)>,
        out: &mut Vec<(u32, [f64; 4], f64)>,
    ) {
        let base = out.len();
        if n == 0 || v >= self.points.len() || !p.is_finite() {
            return;
        }
        let (s, e) = (self.incident_start[v], self.incident_start[v + 1]);
        let o = self.points[v];
        let pv = p - o;
        let incident = &self.incident[s as usize..e as usize];
        self.bound_incident(incident, v, pv, bounds);
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

    /// The tets of `incident` (those at cloud point `v`) whose closest point to `v + pv` may
    /// not be `v` itself, each with a lower bound of its distance, into `bounds`: filtered and
    /// bounded from the inline corners, without loading the tets or their frames.
    fn bound_incident(
        &self,
        incident: &[Incident],
        v: usize,
        pv: DVec3,
        bounds: &mut Vec<(f64, u32)>,
    ) {
        let o = self.points[v];
        // The corner test's margin, squared: pv·e < −1e-9 |pv| |e| without square roots.
        let margin2 = 1e-18 * pv.length_squared();
        bounds.clear();
        for (i, inc) in incident.iter().enumerate() {
            let edge = |k: usize| self.points[inc.others[k] as usize] - o;
            let e = [edge(0), edge(1), edge(2)];
            // The closest point is certainly the corner itself when pv makes an obtuse angle,
            // with margin, with every edge leaving it (pv lies in the tet's normal cone there);
            // such tets are dropped (the corner is scored on its own), borderline ones kept.
            let corner = (0..3).all(|j| {
                let d = pv.dot(e[j]);
                inc.others[j] as usize == v || (d < 0.0 && d * d > margin2 * e[j].length_squared())
            });
            if corner {
                continue;
            }
            let lb = if inc.tag & FLAT != 0 {
                0.0
            } else {
                plane_lower_bound(e, pv)
            };
            bounds.push((lb, i as u32));
        }
    }

    /// The cloud point nearest to `p` (ties: lowest index); 0 for an empty cloud.
    fn nearest_point(&self, p: DVec3) -> usize {
        first_nearest(self.points.iter().map(|q| q.distance_squared(p)))
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

    pub(super) fn build_bvh(&mut self, boxes: &[(DVec3, DVec3)]) {
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

/// The position of the first smallest of the squared distances `d2`, 0 when there are none:
/// the cloud point nearest to a query, ties to the lowest index. Squared distances are ≥ 0
/// (never −0), so `<` orders them as a total order would; a non-finite query, whose
/// distances are NaN or infinite, gets 0 (and is not projected).
pub(crate) fn first_nearest(d2: impl IntoIterator<Item = f64>) -> usize {
    let mut best = (0, f64::INFINITY);
    for (i, d) in d2.into_iter().enumerate() {
        if d < best.1 {
            best = (i, d);
        }
    }
    best.0
}

/// A lower bound of the distance from `o + pv` to the non-flat tet with corners `o` and
/// `o + e[j]`: the largest distance beyond one of its face planes (on the side away from the
/// opposite corner); 0 for a point inside. Everything is relative to `o`: the three faces at
/// `o` have normals `e[j] × e[j+1]`, the fourth their sum, and every face's normal meets its
/// opposite corner with the same triple product `det` (the far face's at `−det`).
pub(super) fn plane_lower_bound(e: [DVec3; 3], pv: DVec3) -> f64 {
    let n = [e[0].cross(e[1]), e[1].cross(e[2]), e[2].cross(e[0])];
    let det = e[2].dot(n[0]);
    let far = n[0] + n[1] + n[2];
    // Each face's offset along its normal, signed so that the opposite corner is at `det`:
    // beyond the face (away from that corner) is the opposite sign.
    let side = -det.signum();
    let faces = [
        (n[0], n[0].dot(pv)),
        (n[1], n[1].dot(pv)),
        (n[2], n[2].dot(pv)),
        (far, det - far.dot(pv)),
    ];
    // The largest squared distance beyond a face plane, with one square root at the end.
    let mut lb2 = 0.0f64;
    for (n, beyond) in faces {
        if beyond * side > 0.0 {
            lb2 = lb2.max(beyond * beyond / n.length_squared());
        }
    }
    let lb = lb2.sqrt();
    if lb.is_finite() && det != 0.0 {
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
