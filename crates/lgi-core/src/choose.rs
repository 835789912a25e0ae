//! Candidate choice for one bundle in one frame: among all local geometries that pass through
//! the bundle (every tet containing its target), pick the one that best explains the bundle's
//! natural neighbours; outside every tet, project onto the nearest tets and score the same way.
//!
//! A candidate is a convex combination of cloud points; each point may stand for several
//! shapes (its aliases: shapes that do not move this bundle, or move it identically). Which
//! alias is used does not change the bundle but does change its neighbours, so the best
//! candidates also pick their aliases by the neighbour score.

use crate::cloud::BundleCloud;
use crate::tet_index::{first_nearest, TetIndex};
use glam::DVec3;

/// Marks "no tet" in [`Choice::tet`] (the cloud had no tets, or a point/segment/triangle was used).
pub const NO_TET: u32 = u32::MAX;

/// The chosen local geometry of one bundle: `x = x0 + Σ weights[j] s_{shapes[j]}` with shape
/// id 0 the neutral (zero displacement) and id k ≥ 1 the dataset's shape k − 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    /// Shape ids (0 = neutral); unused slots have weight 0.
    pub shapes: [u32; 4],
    /// Convex weights (≥ 0, sum 1).
    pub weights: [f64; 4],
    /// Tet of the bundle's index that was used, or [`NO_TET`].
    pub tet: u32,
    /// True when the target was outside every tet and was projected.
    pub projected: bool,
    /// Distance from the target to the chosen geometry's bundle position (0 inside).
    pub distance: f64,
    /// True when the bundle took the frame's global fit ([`crate::prior`]) instead of a tet:
    /// its geometry is the fit's weights, `shapes`/`weights` are then unused (weights 0).
    pub fit: bool,
}

impl Choice {
    /// A bundle whose piece is a fit (the frame's global fit, or a caller's own) instead of a
    /// tet: no shapes, `distance` from its target to the fit's bundle position.
    pub fn of_fit(distance: f64) -> Choice {
        Choice {
            shapes: [0; 4],
            weights: [0.0; 4],
            tet: NO_TET,
            projected: false,
            distance,
            fit: true,
        }
    }
}

/// What the score of a candidate needs to know about the frame around the bundle.
pub struct Scoring<'a> {
    /// Bundle surface positions on every shape, `(S + 1) × B`, index `[k * B + n]`.
    pub shape_positions: &'a [DVec3],
    /// Number of bundles B.
    pub num_bundles: usize,
    /// The bundle's natural neighbours (bundle indices).
    pub neighbours: &'a [u32],
    /// The frame's targets for all bundles (NaN rows are missing and ignored).
    pub targets: &'a [DVec3],
    /// The previous frame's choice for this bundle, if any.
    pub previous: Option<&'a Choice>,
    /// Penalty per shape of a candidate that the previous choice did not use (data units²).
    pub temporal_weight: f64,
    /// Per shape id, the error over all bundles of that shape alone
    /// ([`FrameErrors::pure`]): the same for every bundle of a frame, so the tie-break of
    /// pure candidates is a lookup. Empty to compute on demand.
    pub pure_errors: &'a [f64],
    /// `|P[k][n] − t_n|²` for every shape id k and bundle n ([`FrameErrors::distances`]):
    /// the neighbour error of a cloud point alone is then a sum of lookups. Empty to compute
    /// on demand.
    pub distances: &'a [f64],
}

/// The per-frame tables every bundle's choice shares: computed once per frame.
#[derive(Debug, Clone, Default)]
pub struct FrameErrors {
    /// `|P[k][n] − t_n|²` for every shape id k and bundle n, `(S + 1) × B`, index
    /// `[k * B + n]`; 0 where the target is missing.
    pub distances: Vec<f64>,
    /// `Σ_n |P[k][n] − t_n|²` over the present bundles, for every shape id k: the global
    /// error of a bundle choosing shape k alone.
    pub pure: Vec<f64>,
}

impl FrameErrors {
    /// The tables for one frame's `targets` (NaN rows are missing).
    pub fn new(shape_positions: &[DVec3], num_bundles: usize, targets: &[DVec3]) -> Self {
        let b = num_bundles.max(1);
        // Plain loops into a zeroed table: as a flat_map it took ~35 instructions an entry.
        // Missing targets' entries stay 0, so a row's sum is over the present bundles.
        let mut distances = vec![0.0; shape_positions.len()];
        let mut pure = vec![0.0; distances.len().div_ceil(b)];
        for ((row, out), pure) in shape_positions
            .chunks(b)
            .zip(distances.chunks_mut(b))
            .zip(&mut pure)
        {
            for ((p, t), d) in row.iter().zip(targets).zip(out.iter_mut()) {
                if !t.is_nan() {
                    *d = p.distance_squared(*t);
                }
            }
            *pure = out.iter().sum();
        }
        FrameErrors { distances, pure }
    }
}

impl Scoring<'_> {
    /// Squared distances of the neighbours to their positions under the geometry.
    fn neighbour_error(&self, shapes: &[u32; 4], weights: &[f64; 4]) -> f64 {
        self.error_over(self.neighbours.iter().copied(), shapes, weights)
    }

    /// The same error over every bundle: breaks exact ties between aliases that no
    /// neighbour can tell apart (shapes identical around this bundle but not elsewhere).
    fn global_error(&self, shapes: &[u32; 4], weights: &[f64; 4]) -> f64 {
        if let Some(j) = (0..4).find(|&j| weights[j] == 1.0) {
            if let Some(&e) = self.pure_errors.get(shapes[j] as usize) {
                return e;
            }
        }
        self.error_over(0..self.num_bundles as u32, shapes, weights)
    }

    fn error_over(
        &self,
        bundles: impl Iterator<Item = u32>,
        shapes: &[u32; 4],
        weights: &[f64; 4],
    ) -> f64 {
        let b = self.num_bundles;
        let mut err = 0.0;
        for n in bundles {
            let t = self.targets[n as usize];
            if t.is_nan() {
                continue;
            }
            let mut x = DVec3::ZERO;
            for j in 0..4 {
                if weights[j] != 0.0 {
                    x += self.shape_positions[shapes[j] as usize * b + n as usize] * weights[j];
                }
            }
            err += x.distance_squared(t);
        }
        err
    }

    /// The score of cloud point `shape` alone at `own_distance`: bit for bit
    /// [`score`](Self::score) of `[shape; 4]` with weights `[1, 0, 0, 0]`.
    fn point_score(&self, shape: u32, own_distance: f64) -> f64 {
        let (shapes, weights) = ([shape; 4], [1.0, 0.0, 0.0, 0.0]);
        let (b, k) = (self.num_bundles, shape as usize);
        let neighbour_error = match self.distances.get(k * b..(k + 1) * b) {
            // A missing neighbour's entry is 0: adding it changes nothing, as skipping it.
            Some(row) => self
                .neighbours
                .iter()
                .fold(0.0, |e, &n| e + row[n as usize]),
            None => self.neighbour_error(&shapes, &weights),
        };
        neighbour_error + own_distance * own_distance + self.point_penalty(shape)
    }

    /// [`temporal_penalty`](Self::temporal_penalty) of `[shape; 4]` with weights
    /// `[1, 0, 0, 0]`, bit for bit: one fresh shape unless the previous choice used it.
    fn point_penalty(&self, shape: u32) -> f64 {
        let Some(prev) = self.previous else {
            return 0.0;
        };
        self.temporal_weight * if uses(prev, shape) { 0.0 } else { 1.0 }
    }

    fn temporal_penalty(&self, shapes: &[u32; 4], weights: &[f64; 4]) -> f64 {
        let Some(prev) = self.previous else {
            return 0.0;
        };
        let fresh = (0..4)
            .filter(|&j| weights[j] != 0.0 && !uses(prev, shapes[j]))
            .count();
        self.temporal_weight * fresh as f64
    }

    /// The score [`choose`] gave `choice` (a tet's or a cloud point's): what another candidate
    /// must beat.
    pub fn choice_score(&self, choice: &Choice) -> f64 {
        self.score(&choice.shapes, &choice.weights, choice.distance)
    }

    /// The score of a candidate whose bundle positions are `positions` (B): its squared
    /// distances at the neighbours and at the bundle itself (`own`), plus the temporal
    /// penalty of 4 fresh shapes unless the previous choice was the same kind (`fit`).
    pub fn positions_score(&self, positions: &[DVec3], own: usize, fit: bool) -> f64 {
        let mut err = 0.0;
        for n in self.neighbours.iter().map(|&n| n as usize).chain([own]) {
            let t = self.targets[n];
            if !t.is_nan() {
                err += positions[n].distance_squared(t);
            }
        }
        let fresh = match self.previous {
            Some(p) if p.fit == fit => 0.0,
            Some(_) => 4.0,
            None => 0.0,
        };
        err + self.temporal_weight * fresh
    }

    fn score(&self, shapes: &[u32; 4], weights: &[f64; 4], own_distance: f64) -> f64 {
        self.neighbour_error(shapes, weights)
            + own_distance * own_distance
            + self.temporal_penalty(shapes, weights)
    }
}

/// True when `choice` gives shape `s` a weight.
fn uses(choice: &Choice, s: u32) -> bool {
    (0..4).any(|j| choice.weights[j] != 0.0 && choice.shapes[j] == s)
}

/// Tuning of the choice.
#[derive(Debug, Clone, Copy)]
pub struct ChoiceParams {
    /// Containment tolerance on barycentric coordinates.
    pub eps: f64,
    /// Nearest tets considered when the target is outside every tet.
    pub projection_candidates: usize,
    /// Best candidates (by representative shapes) whose aliases are then optimised.
    pub alias_refine: usize,
    /// A target this close to a cloud point is a hit on that point (absolute).
    pub hit_distance: f64,
}

impl Default for ChoiceParams {
    fn default() -> Self {
        ChoiceParams {
            eps: 1e-9,
            projection_candidates: 8,
            alias_refine: 4,
            hit_distance: 0.0,
        }
    }
}

/// A scored candidate: (score, tet, cloud points, weights, distance to the target).
type Scored = (f64, u32, [u32; 4], [f64; 4], f64);

/// Reusable buffers of one worker.
#[derive(Default)]
pub struct Scratch {
    inside: Vec<(u32, [f64; 4])>,
    nearest: Vec<(u32, [f64; 4], f64)>,
    bounds: Vec<(f64, u32)>,
    scored: Vec<Scored>,
    /// Squared distance of every cloud point to the target.
    point_d2: Vec<f64>,
}

/// The `k` lowest scores seen so far (k is small: `alias_refine`), for pruning candidates
/// whose lower bound cannot enter them.
struct BestScores {
    k: usize,
    scores: [f64; 8],
    len: usize,
}

impl BestScores {
    /// Beyond 8 nothing is pruned (`worst` stays infinite).
    fn new(k: usize) -> Self {
        BestScores {
            k,
            scores: [f64::INFINITY; 8],
            len: 0,
        }
    }

    fn add(&mut self, s: f64) {
        if self.k > self.scores.len() {
            return;
        }
        if self.len < self.k {
            self.scores[self.len] = s;
            self.len += 1;
        } else if s < self.scores[self.len - 1] {
            self.scores[self.len - 1] = s;
        } else {
            return;
        }
        self.scores[..self.len].sort_unstable_by(f64::total_cmp);
    }

    /// False when `s` is above the k lowest seen so far, which only fall: a candidate
    /// scoring `s` can then never be among the final k (ties and NaN are admitted).
    fn admits(&self, s: f64) -> bool {
        s <= self.worst() || s.is_nan()
    }

    /// The k-th lowest score (infinity until k scores were added).
    fn worst(&self) -> f64 {
        if self.len < self.k {
            f64::INFINITY
        } else {
            self.scores[self.len - 1]
        }
    }
}

fn clean_weights(l: [f64; 4]) -> [f64; 4] {
    let mut w = l.map(|x| if x > 1e-12 { x } else { 0.0 });
    let s: f64 = w.iter().sum();
    if s > 0.0 {
        for x in &mut w {
            *x /= s;
        }
    }
    w
}

/// Chooses the local geometry of one bundle for `target`. `index` is the tet index over
/// `cloud`'s points (its tets' corners are cloud points; the nearest one is found from the
/// cloud's distances).
pub fn choose(
    index: &TetIndex,
    cloud: &BundleCloud,
    groups: &[AliasGroups],
    target: DVec3,
    scoring: &Scoring<'_>,
    params: &ChoiceParams,
    scratch: &mut Scratch,
) -> Choice {
    let reps = |tet: &[u32; 4]| tet.map(|p| cloud.aliases[p as usize][0]);
    scratch.scored.clear();
    // Every cloud point's squared distance, once: the nearest point, the hits and the
    // points as candidates all read them (`d` below is `q.distance(target)` bit for bit).
    scratch.point_d2.clear();
    scratch
        .point_d2
        .extend(cloud.points.iter().map(|&q| (q - target).length_squared()));
    // A point with d² beyond `limit · (1 + 1e-12)` certainly has d > limit^½ and d·d > limit
    // (the rounding of d = √d² and of d·d is ~1e-16 relative): it is skipped without d.
    let beyond = |d2: f64, limit: f64| d2 > limit * (1.0 + 1e-12);
    let hit2 = params.hit_distance * params.hit_distance;
    scratch.inside.clear();
    index.query(target, params.eps, &mut scratch.inside);
    let projected = scratch.inside.is_empty();
    if !projected {
        for &(t, l) in &scratch.inside {
            let tet = index.tets()[t as usize];
            let w = clean_weights(l);
            let shapes = reps(&tet);
            let s = scoring.score(&shapes, &w, 0.0);
            scratch.scored.push((s, t, tet, w, 0.0));
        }
        // A target on a cloud point is that shape exactly, even where every tet at the point
        // was too thin to keep and the target only lies inside other tets.
        for (p, &d2) in scratch.point_d2.iter().enumerate() {
            if beyond(d2, hit2) {
                continue;
            }
            let d = d2.sqrt();
            if d <= params.hit_distance {
                let tet = [p as u32; 4];
                let w = [1.0, 0.0, 0.0, 0.0];
                let s = scoring.point_score(cloud.aliases[p][0], d);
                scratch.scored.push((s, NO_TET, tet, w, d));
            }
        }
    } else if index.num_tets() > 0 {
        scratch.nearest.clear();
        // Tets around the cloud point nearest the target (where it left the cloud):
        // the exact n-nearest search must enumerate every tet tied at a shared vertex and
        // costs ~10x more for the same choices in practice (docs/performance.md). A closest
        // point at a tet's vertex is that cloud point, scored below on its own.
        index.project_around_point(
            target,
            first_nearest(scratch.point_d2.iter().copied()),
            params.projection_candidates,
            &mut scratch.bounds,
            &mut scratch.nearest,
        );
        let mut best = BestScores::new(params.alias_refine.max(1));
        for &(t, l, d) in &scratch.nearest {
            let tet = index.tets()[t as usize];
            let w = clean_weights(l);
            let s = scoring.score(&reps(&tet), &w, d);
            best.add(s);
            // Beyond the best few so far it can never enter them (nor is it a hit): dropped.
            if best.admits(s) {
                scratch.scored.push((s, t, tet, w, d));
            }
        }
        // Cloud points themselves: a point whose every tet was too thin to keep is still
        // real geometry, and a target on it must find it exactly. A score is at least the
        // squared distance, so a point farther than the current best few cannot enter them
        // (hits are always kept: their aliases are refined).
        for (p, &d2) in scratch.point_d2.iter().enumerate() {
            if beyond(d2, hit2.max(best.worst())) {
                continue;
            }
            let d = d2.sqrt();
            if d > params.hit_distance && d * d > best.worst() {
                continue;
            }
            let tet = [p as u32; 4];
            let w = [1.0, 0.0, 0.0, 0.0];
            let s = scoring.point_score(cloud.aliases[p][0], d);
            best.add(s);
            if best.admits(s) || d <= params.hit_distance {
                scratch.scored.push((s, NO_TET, tet, w, d));
            }
        }
    } else {
        lower_simplices(cloud, target, scoring, &mut scratch.scored);
    }
    // Only the best few need ordering (a total order: score, tet, points), not all candidates.
    let order =
        |a: &Scored, b: &Scored| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2));
    let refine = params.alias_refine.max(1);
    if scratch.scored.len() > refine {
        scratch.scored.select_nth_unstable_by(refine - 1, order);
    }
    let head = refine.min(scratch.scored.len());
    scratch.scored[..head].sort_unstable_by(order);
    // Refine the best few, and every exact hit on a cloud point: a hit's representative may
    // score badly (the neutral standing for every shape that does not move this bundle) while
    // one of its aliases is exactly right. The hits beyond the best few follow them in the
    // same order (an exact tie of refined scores goes to the first).
    let hit = |c: &Scored| c.1 == NO_TET && c.4 <= params.hit_distance;
    let mut kept = head;
    for i in head..scratch.scored.len() {
        if hit(&scratch.scored[i]) {
            scratch.scored.swap(kept, i);
            kept += 1;
        }
    }
    scratch.scored[head..kept].sort_unstable_by(order);
    let mut best: Option<(f64, Choice)> = None;
    for &(_, t, tet, w, d) in &scratch.scored[..kept] {
        let shapes = refine_aliases(cloud, groups, &tet, &w, scoring);
        let s = scoring.score(&shapes, &w, d);
        let choice = Choice {
            shapes,
            weights: w,
            tet: t,
            projected,
            distance: d,
            fit: false,
        };
        if best.as_ref().is_none_or(|(bs, _)| s < *bs) {
            best = Some((s, choice));
        }
    }
    best.map(|(_, c)| c).unwrap_or(Choice {
        shapes: [0; 4],
        weights: [1.0, 0.0, 0.0, 0.0],
        tet: NO_TET,
        projected: true,
        distance: target.distance(cloud.points[0]),
        fit: false,
    })
}

/// Greedy per-vertex alias choice: each point with weight takes the alias that minimises the
/// neighbour error with the others fixed. Exact ties go to the alias with the lower error over
/// all bundles, then to the lowest shape id (deterministic).
fn refine_aliases(
    cloud: &BundleCloud,
    groups: &[AliasGroups],
    tet: &[u32; 4],
    w: &[f64; 4],
    scoring: &Scoring<'_>,
) -> [u32; 4] {
    let mut shapes = tet.map(|p| cloud.aliases[p as usize][0]);
    let mut tied: Vec<usize> = Vec::new();
    for j in 0..4 {
        let point_groups = &groups[tet[j] as usize];
        if w[j] == 0.0 || cloud.aliases[tet[j] as usize].len() < 2 {
            continue;
        }
        // Aliases identical at every neighbour form a group: one neighbour error per group.
        let mut best = f64::INFINITY;
        tied.clear();
        for (g, members) in point_groups.iter().enumerate() {
            let mut trial = shapes;
            trial[j] = members[0];
            let e = scoring.neighbour_error(&trial, w);
            if e < best {
                best = e;
                tied.clear();
                tied.push(g);
            } else if e == best {
                tied.push(g);
            }
        }
        let mut winner = (f64::INFINITY, u32::MAX);
        let single = tied.len() == 1 && point_groups[tied[0]].len() == 1;
        for &g in &tied {
            for &a in &point_groups[g] {
                if single {
                    winner = (0.0, a);
                    continue;
                }
                // Exact tie at the neighbours: let the whole face decide, then the lower id.
                let mut trial = shapes;
                trial[j] = a;
                let e = scoring.global_error(&trial, w);
                if e < winner.0 || (e == winner.0 && a < winner.1) {
                    winner = (e, a);
                }
            }
        }
        if winner.1 != u32::MAX {
            shapes[j] = winner.1;
        }
    }
    shapes
}

/// One cloud point's aliases split into groups whose bundle positions agree exactly at every
/// natural neighbour (first member of each group is its lowest shape id).
pub type AliasGroups = Vec<Vec<u32>>;

/// Groups the aliases of every point of `cloud` by their positions at `neighbours`.
pub fn alias_groups(
    cloud: &BundleCloud,
    neighbours: &[u32],
    shape_positions: &[DVec3],
    num_bundles: usize,
) -> Vec<AliasGroups> {
    cloud
        .aliases
        .iter()
        .map(|aliases| {
            let mut groups: Vec<(Vec<[u64; 3]>, Vec<u32>)> = Vec::new();
            for &a in aliases {
                let key: Vec<[u64; 3]> = neighbours
                    .iter()
                    .map(|&n| {
                        let p = shape_positions[a as usize * num_bundles + n as usize];
                        [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]
                    })
                    .collect();
                match groups.iter_mut().find(|(k, _)| *k == key) {
                    Some((_, m)) => m.push(a),
                    None => groups.push((key, vec![a])),
                }
            }
            groups
                .into_iter()
                .map(|(_, mut m)| {
                    m.sort_unstable();
                    m
                })
                .collect()
        })
        .collect()
}

/// Clouds with no tets (fewer than 4 points, or all coplanar): closest points of the cloud's
/// points, segments and (for small clouds) triangles, scored like tets.
fn lower_simplices(
    cloud: &BundleCloud,
    target: DVec3,
    scoring: &Scoring<'_>,
    out: &mut Vec<Scored>,
) {
    let pts = &cloud.points;
    let n = pts.len().min(24);
    let mut push = |simplex: [u32; 4], w: [f64; 4], q: DVec3| {
        let d = q.distance(target);
        let shapes = simplex.map(|p| cloud.aliases[p as usize][0]);
        let w = clean_weights(w);
        out.push((scoring.score(&shapes, &w, d), NO_TET, simplex, w, d));
    };
    for a in 0..n {
        push([a as u32; 4], [1.0, 0.0, 0.0, 0.0], pts[a]);
        for b in (a + 1)..n {
            let ab = pts[b] - pts[a];
            let t = if ab.length_squared() > 0.0 {
                ((target - pts[a]).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            push(
                [a as u32, b as u32, b as u32, b as u32],
                [1.0 - t, t, 0.0, 0.0],
                pts[a] + ab * t,
            );
            for c in (b + 1)..n {
                let (q, bary) =
                    crate::geom::closest_point_on_triangle(target, pts[a], pts[b], pts[c]);
                push(
                    [a as u32, b as u32, c as u32, c as u32],
                    [bary[0], bary[1], bary[2], 0.0],
                    q,
                );
            }
        }
    }
}

#[cfg(test)]
mod tests;
