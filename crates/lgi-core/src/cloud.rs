//! One bundle's point cloud: the distinct positions the bundle takes over the dataset's shapes.
//! Shapes that barely move the bundle, and near-duplicate positions, are folded into aliases so
//! the tetrahedra built on the cloud are not degenerate, while no shape id is ever lost.

use std::collections::HashMap;

use glam::DVec3;

use crate::error::{LgiError, Result};

/// One bundle's point cloud: distinct positions of the bundle over the dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct BundleCloud {
    /// `points[p]` is a position; `points[0]` is always the neutral position (shape id 0).
    pub points: Vec<DVec3>,
    /// `aliases[p]`: every shape id whose bundle position coincides with `points[p]`, ascending;
    /// the first is the representative (the shape whose position `points[p]` is), and for
    /// `p = 0` it is 0. Pruned shapes (moving the bundle less than the prune distance) are
    /// aliases of point 0; near-duplicates (within the duplicate distance of an earlier kept
    /// point) are aliases of the nearest such point.
    pub aliases: Vec<Vec<u32>>,
}

impl BundleCloud {
    /// Number of distinct points.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Never true for a cloud made by [`build_cloud`] (the neutral is always a point).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
}

/// Builds the cloud of one bundle from its position on every shape.
///
/// `positions[k]` is the bundle's position on shape id `k` (`positions[0]` = neutral). Shapes are
/// visited in id order: shape `k` is *pruned* (alias of point 0) when
/// `|positions[k] - positions[0]| < prune_motion`; otherwise, if some kept point lies within
/// `duplicate_distance` (inclusive) of it, it becomes an alias of the nearest such point (ties:
/// the earliest); otherwise it is a new point. Both distances are absolute (the caller scales them
/// by the face's size). The duplicate search uses a hash grid with cells of the duplicate
/// distance, so it is linear in the number of shapes for well-spread clouds.
///
/// Errors: [`LgiError::Input`] when `positions` is empty, a position is not finite (naming the
/// shape id), or a distance is negative or not finite.
pub fn build_cloud(
    positions: &[DVec3],
    prune_motion: f64,
    duplicate_distance: f64,
) -> Result<BundleCloud> {
    if positions.is_empty() {
        return Err(LgiError::Input(
            "a bundle cloud needs at least the neutral position (shape id 0)".into(),
        ));
    }
    for (name, value) in [
        ("prune_motion", prune_motion),
        ("duplicate_distance", duplicate_distance),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(LgiError::Input(format!(
                "{name} must be a finite distance >= 0, got {value}"
            )));
        }
    }
    if let Some(k) = positions.iter().position(|p| !p.is_finite()) {
        let what = if k == 0 {
            "the neutral (shape id 0)".to_string()
        } else {
            format!("shape id {k} (dataset shape {})", k - 1)
        };
        return Err(LgiError::Input(format!(
            "bundle position on {what} is not finite: {}",
            positions[k]
        )));
    }

    let neutral = positions[0];
    let mut points = vec![neutral];
    let mut aliases = vec![vec![0u32]];
    let mut index = DuplicateIndex::new(duplicate_distance, positions);
    index.insert(neutral, 0);
    for (k, &p) in positions.iter().enumerate().skip(1) {
        let id = k as u32;
        if p.distance(neutral) < prune_motion {
            aliases[0].push(id);
            continue;
        }
        match index.nearest_within(p, &points) {
            Some(q) => aliases[q].push(id),
            None => {
                index.insert(p, points.len() as u32);
                points.push(p);
                aliases.push(vec![id]);
            }
        }
    }
    Ok(BundleCloud { points, aliases })
}

/// Nearest kept point within the duplicate distance: a hash grid when the cell coordinates fit
/// comfortably in integers, otherwise a linear scan (huge coordinates or a zero distance with
/// distinct cells make the grid meaningless).
struct DuplicateIndex {
    radius: f64,
    inv_cell: f64,
    cells: Option<HashMap<[i64; 3], Vec<u32>>>,
}

impl DuplicateIndex {
    /// Keys beyond this stay exact in f64 and far from i64 overflow.
    const MAX_KEY: f64 = 1e15;

    fn new(radius: f64, positions: &[DVec3]) -> Self {
        let inv_cell = if radius > 0.0 { 1.0 / radius } else { 0.0 };
        let grid_ok = radius > 0.0
            && inv_cell.is_finite()
            && positions
                .iter()
                .all(|p| (p.abs().max_element() * inv_cell) < Self::MAX_KEY);
        DuplicateIndex {
            radius,
            inv_cell,
            cells: grid_ok.then(HashMap::new),
        }
    }

    fn key(&self, p: DVec3) -> [i64; 3] {
        let c = (p * self.inv_cell).floor();
        [c.x as i64, c.y as i64, c.z as i64]
    }

    fn insert(&mut self, p: DVec3, point: u32) {
        let key = self.key(p);
        if let Some(cells) = &mut self.cells {
            cells.entry(key).or_default().push(point);
        }
    }

    fn nearest_within(&self, p: DVec3, points: &[DVec3]) -> Option<usize> {
        let mut best: Option<(f64, usize)> = None;
        let mut consider = |q: usize| {
            let d = p.distance(points[q]);
            if d <= self.radius && best.is_none_or(|(bd, bq)| d < bd || (d == bd && q < bq)) {
                best = Some((d, q));
            }
        };
        match &self.cells {
            Some(cells) => {
                let [x, y, z] = self.key(p);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            if let Some(items) = cells.get(&[x + dx, y + dy, z + dz]) {
                                items.iter().for_each(|&q| consider(q as usize));
                            }
                        }
                    }
                }
            }
            None => (0..points.len()).for_each(&mut consider),
        }
        best.map(|(_, q)| q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use proptest::test_runner::{Config, RngSeed};

    /// Independent reference: the same sequential rule with a plain linear scan.
    fn reference(positions: &[DVec3], prune: f64, dup: f64) -> BundleCloud {
        let mut points = vec![positions[0]];
        let mut aliases = vec![vec![0u32]];
        for (k, &p) in positions.iter().enumerate().skip(1) {
            if p.distance(positions[0]) < prune {
                aliases[0].push(k as u32);
                continue;
            }
            let mut best: Option<(f64, usize)> = None;
            for (q, &x) in points.iter().enumerate() {
                let d = p.distance(x);
                if d <= dup && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, q));
                }
            }
            match best {
                Some((_, q)) => aliases[q].push(k as u32),
                None => {
                    points.push(p);
                    aliases.push(vec![k as u32]);
                }
            }
        }
        BundleCloud { points, aliases }
    }

    #[test]
    fn neutral_is_point_zero_and_small_motions_are_its_aliases() {
        let pos = [
            DVec3::ZERO,
            DVec3::new(0.05, 0.0, 0.0), // pruned (< 0.1)
            DVec3::new(1.0, 0.0, 0.0),
            DVec3::new(1.0, 0.005, 0.0), // duplicate of shape 2
            DVec3::new(0.0, 2.0, 0.0),
            DVec3::ZERO, // pruned
        ];
        let c = build_cloud(&pos, 0.1, 0.01).unwrap();
        assert_eq!(c.points, vec![pos[0], pos[2], pos[4]]);
        assert_eq!(c.aliases, vec![vec![0, 1, 5], vec![2, 3], vec![4]]);
    }

    #[test]
    fn every_shape_id_appears_exactly_once_among_aliases() {
        let pos: Vec<DVec3> = (0..50)
            .map(|k| DVec3::new((k % 7) as f64, (k % 5) as f64 * 0.5, 0.0))
            .collect();
        let c = build_cloud(&pos, 0.2, 0.3).unwrap();
        let mut ids: Vec<u32> = c.aliases.iter().flatten().copied().collect();
        ids.sort_unstable();
        assert_eq!(ids, (0..50).collect::<Vec<u32>>());
        assert_eq!(c.aliases[0][0], 0);
    }

    #[test]
    fn zero_distances_keep_all_distinct_positions_and_merge_exact_copies() {
        let pos = [DVec3::ZERO, DVec3::X, DVec3::X, DVec3::Y, DVec3::ZERO];
        let c = build_cloud(&pos, 0.0, 0.0).unwrap();
        assert_eq!(c.points, vec![DVec3::ZERO, DVec3::X, DVec3::Y]);
        assert_eq!(c.aliases, vec![vec![0, 4], vec![1, 2], vec![3]]);
    }

    #[test]
    fn non_finite_position_is_an_input_error_naming_the_shape() {
        let pos = [DVec3::ZERO, DVec3::X, DVec3::new(f64::NAN, 0.0, 0.0)];
        let err = build_cloud(&pos, 0.0, 0.0).unwrap_err();
        assert!(matches!(err, LgiError::Input(_)));
        assert!(err.to_string().contains("shape id 2"), "{err}");
        let neutral_bad = [DVec3::new(0.0, f64::INFINITY, 0.0)];
        assert!(build_cloud(&neutral_bad, 0.0, 0.0)
            .unwrap_err()
            .to_string()
            .contains("neutral"));
    }

    #[test]
    fn empty_input_and_bad_distances_are_input_errors() {
        assert!(matches!(
            build_cloud(&[], 0.0, 0.0),
            Err(LgiError::Input(_))
        ));
        for (prune, dup) in [(-1.0, 0.0), (0.0, f64::NAN), (f64::INFINITY, 0.0)] {
            assert!(matches!(
                build_cloud(&[DVec3::ZERO], prune, dup),
                Err(LgiError::Input(_))
            ));
        }
    }

    #[test]
    fn huge_coordinates_fall_back_to_the_linear_scan() {
        let pos = [
            DVec3::ZERO,
            DVec3::splat(1e300),
            DVec3::splat(1e300) + DVec3::X * 1e285,
        ];
        let c = build_cloud(&pos, 0.0, 1e-3).unwrap();
        assert_eq!(c, reference(&pos, 0.0, 1e-3));
    }

    fn arb_positions() -> impl Strategy<Value = Vec<DVec3>> {
        // A coarse lattice makes exact and near coincidences common.
        prop::collection::vec((-20i32..20, -20i32..20, -5i32..5, 0.0..0.02f64), 1..120).prop_map(
            |v| {
                v.into_iter()
                    .map(|(x, y, z, j)| {
                        DVec3::new(x as f64 * 0.05 + j, y as f64 * 0.05, z as f64 * 0.05)
                    })
                    .collect()
            },
        )
    }

    proptest! {
        #![proptest_config(Config {
            cases: 256,
            rng_seed: RngSeed::Fixed(0x5eed_c10d),
            failure_persistence: None,
            ..Config::default()
        })]

        #[test]
        fn cloud_matches_linear_scan_reference(
            pos in arb_positions(),
            prune in 0.0..0.3f64,
            dup in 0.0..0.2f64,
        ) {
            let c = build_cloud(&pos, prune, dup).unwrap();
            prop_assert_eq!(&c, &reference(&pos, prune, dup));
            // Kept points are pairwise farther apart than the duplicate distance.
            for i in 0..c.points.len() {
                for j in 0..i {
                    prop_assert!(c.points[i].distance(c.points[j]) > dup);
                }
            }
        }
    }
}
