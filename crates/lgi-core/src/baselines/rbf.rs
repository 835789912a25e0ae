//! The 3D biharmonic RBF interpolator (φ(r) = r plus a linear polynomial) of the baselines: the
//! displacement-interpolation baseline spreads marker displacements with it, LGI-RBF its residual
//! correction. Simple, smooth, exact at the markers and linear in the data, so a V×B
//! interpolation matrix is computed once and applied to every frame.

use crate::correspond::correspond;
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::frame_blocks::frame_blocks;
use crate::linalg::Lu;
use crate::simd::with_avx2;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// A marker's constraint: its value is the barycentric combination of three vertex values, so
/// the reconstructed mesh passes through the marker exactly (not only the smooth field).
pub type Sample = ([u32; 3], [f64; 3]);

/// Biharmonic RBF interpolation of per-marker values (displacements) over mesh vertices.
///
/// Centres are the markers' rest surface points; each marker's constraint is sampled like the
/// mesh samples it (barycentric combination of its triangle's vertices), so applying the
/// interpolated displacements to the vertices reproduces every present marker exactly.
#[derive(Debug)]
pub struct RbfInterpolator {
    points: Vec<DVec3>,
    centres: Vec<DVec3>,
    samples: Vec<Sample>,
    matrix: Vec<f64>,
    // Missing markers change the system: its factorisation is cached per set of present ones.
    cache: Mutex<HashMap<Vec<bool>, Arc<Lu>>>,
}

/// Factorisations kept for sets of missing markers (each (B+4)² values).
const MAX_CACHED: usize = 256;

/// Points per parallel task of [`RbfInterpolator::add_interpolated_frames`].
const RBF_BLOCK: usize = 256;

/// The first marker value that is neither finite nor wholly NaN (a missing marker), if any.
fn first_unreadable(values: &[DVec3]) -> Option<usize> {
    values.iter().position(|p| p.is_finite() == p.is_nan())
}

fn kernel(a: DVec3, b: DVec3) -> f64 {
    (a - b).length()
}

impl RbfInterpolator {
    /// Interpolation over `points` (V) with one constraint per sample; the centres are the
    /// samples' positions on `points`. Errors: indices out of range, fewer than 4 samples, or
    /// a singular system (samples coplanar or coincident) as [`LgiError::Input`].
    pub fn new(points: Vec<DVec3>, samples: Vec<Sample>) -> Result<Self> {
        let v = points.len();
        if samples.len() < 4 {
            return Err(LgiError::Input(format!(
                "RBF interpolation needs at least 4 markers, got {}",
                samples.len()
            )));
        }
        let mut centres = Vec::with_capacity(samples.len());
        for (i, (idx, w)) in samples.iter().enumerate() {
            if idx.iter().any(|&j| j as usize >= v) || w.iter().any(|x| !x.is_finite()) {
                return Err(LgiError::Input(format!(
                    "marker {i}: sample vertices {idx:?} out of range or weights {w:?} not finite"
                )));
            }
            centres.push(
                idx.iter()
                    .zip(w)
                    .fold(DVec3::ZERO, |acc, (&j, &wj)| acc + points[j as usize] * wj),
            );
        }
        if let Some(i) = points.iter().position(|p| !p.is_finite()) {
            return Err(LgiError::Input(format!("point {i} is not finite")));
        }
        let mut me = RbfInterpolator {
            points,
            centres,
            samples,
            matrix: Vec::new(),
            cache: Mutex::new(HashMap::new()),
        };
        let all = vec![true; me.samples.len()];
        let lu = me.factor(&all)?;
        me.matrix = me.build_matrix(&lu);
        if let Ok(mut c) = me.cache.lock() {
            c.insert(all, lu);
        }
        Ok(me)
    }

    /// Markers located on the dataset's neutral (closest surface point, at most `tolerance`
    /// away in data units), interpolating over the neutral's vertices.
    pub fn from_dataset(dataset: &Dataset, markers_rest: &[DVec3], tolerance: f64) -> Result<Self> {
        let mesh = dataset.neutral();
        let found = correspond(mesh, markers_rest, tolerance)?;
        let samples = found
            .iter()
            .map(|(sp, _)| {
                let t = mesh.triangles[sp.triangle as usize];
                (t, sp.bary)
            })
            .collect();
        Self::new(mesh.positions.clone(), samples)
    }

    /// Number of markers B.
    pub fn num_markers(&self) -> usize {
        self.samples.len()
    }

    /// Number of interpolation points V.
    pub fn num_points(&self) -> usize {
        self.points.len()
    }

    /// The markers' constraints (triangle vertices and barycentric weights).
    pub fn samples(&self) -> &[Sample] {
        &self.samples
    }

    /// The RBF centres: the markers' surface points.
    pub fn centres(&self) -> &[DVec3] {
        &self.centres
    }

    /// Row-major V×B matrix mapping marker values to point values (all markers present).
    pub fn matrix(&self) -> &[f64] {
        &self.matrix
    }

    /// Saddle system [[L Φ, L P], [Pᵀ, 0]] over the present markers, `L` the sampling.
    fn factor(&self, present: &[bool]) -> Result<Arc<Lu>> {
        let idx: Vec<usize> = (0..present.len()).filter(|&i| present[i]).collect();
        let n = idx.len();
        if n < 4 {
            return Err(LgiError::Input(format!(
                "RBF interpolation needs at least 4 present markers, got {n}"
            )));
        }
        let m = n + 4;
        let mut a = vec![0.0; m * m];
        for (r, &i) in idx.iter().enumerate() {
            let (vs, ws) = self.samples[i];
            for (c, &j) in idx.iter().enumerate() {
                a[r * m + c] = vs
                    .iter()
                    .zip(&ws)
                    .map(|(&v, &w)| w * kernel(self.points[v as usize], self.centres[j]))
                    .sum();
            }
            let p = self.centres[i];
            let wsum: f64 = ws.iter().sum();
            for (k, val) in [wsum, p.x, p.y, p.z].into_iter().enumerate() {
                a[r * m + n + k] = val;
            }
        }
        for (c, &j) in idx.iter().enumerate() {
            let p = self.centres[j];
            for (k, val) in [1.0, p.x, p.y, p.z].into_iter().enumerate() {
                a[(n + k) * m + c] = val;
            }
        }
        Lu::factor(m, a).map(Arc::new).map_err(|_| {
            LgiError::Input("RBF system is singular: markers coplanar or coincident".into())
        })
    }

    fn lu_for(&self, present: &[bool]) -> Result<Arc<Lu>> {
        if let Ok(c) = self.cache.lock() {
            if let Some(lu) = c.get(present) {
                return Ok(lu.clone());
            }
        }
        let lu = self.factor(present)?;
        if let Ok(mut c) = self.cache.lock() {
            // Random dropouts make most sets unique: bound the memory, keep the full set.
            if c.len() >= MAX_CACHED {
                c.retain(|k, _| k.iter().all(|&p| p));
            }
            c.insert(present.to_vec(), lu.clone());
        }
        Ok(lu)
    }

    /// V×B matrix E · A⁻¹[:, :B] with E = [φ(|p − x_c|), 1, p] (all markers present).
    fn build_matrix(&self, lu: &Lu) -> Vec<f64> {
        let b = self.samples.len();
        let m = b + 4;
        // Columns of A⁻¹ restricted to the marker rows, three unit vectors at a time.
        let mut inv = vec![0.0; m * b];
        for c0 in (0..b).step_by(3) {
            let mut rhs = vec![[0.0; 3]; m];
            for d in 0..3 {
                if c0 + d < b {
                    rhs[c0 + d][d] = 1.0;
                }
            }
            let x = lu.solve3(&rhs);
            for (r, xr) in x.iter().enumerate() {
                for d in 0..3 {
                    if c0 + d < b {
                        inv[r * b + c0 + d] = xr[d];
                    }
                }
            }
        }
        let mut out = vec![0.0; self.points.len() * b];
        out.par_chunks_mut(b).enumerate().for_each(|(v, row)| {
            let p = self.points[v];
            let mut e: Vec<f64> = self.centres.iter().map(|&c| kernel(p, c)).collect();
            e.extend([1.0, p.x, p.y, p.z]);
            for (k, ek) in e.iter().enumerate() {
                let src = &inv[k * b..(k + 1) * b];
                for (o, s) in row.iter_mut().zip(src) {
                    *o += ek * s;
                }
            }
        });
        out
    }

    /// Adds each frame's interpolation of its marker values (`values` F × B, as
    /// [`interpolate`](Self::interpolate) reads them) to its points in `out` (F × V, frame
    /// after frame): `out[f][v] += interpolate(values[f])[v]`, the same bits. The frames with
    /// every marker present share one pass over the matrix (each block of its rows read once
    /// for all of them, not once a frame); the others are interpolated one by one.
    pub fn add_interpolated_frames(&self, values: &[DVec3], out: &mut [DVec3]) -> Result<()> {
        let (b, v) = (self.samples.len(), self.points.len());
        let frames = values.len() / b.max(1);
        if values.len() != frames * b || out.len() != frames * v {
            return Err(LgiError::Input(format!(
                "expected frames of {b} marker values and of {v} points, got {} values and {} points",
                values.len(),
                out.len()
            )));
        }
        if let Some(i) = first_unreadable(values) {
            return Err(LgiError::Input(format!(
                "frame {}: marker value {} is infinite or partly NaN",
                i / b,
                i % b
            )));
        }
        let whole: Vec<bool> = values
            .chunks(b)
            .map(|f| f.iter().all(|p| p.is_finite()))
            .collect();
        for (f, o) in out.chunks_mut(v.max(1)).enumerate() {
            if !whole[f] {
                let c = self.interpolate(&values[f * b..(f + 1) * b])?;
                o.iter_mut().zip(c).for_each(|(o, c)| *o += c);
            }
        }
        let full: Vec<usize> = (0..frames).filter(|&f| whole[f]).collect();
        if full.is_empty() {
            return Ok(());
        }
        // The present frames' values marker by marker (B × 3n): a row's products with every
        // frame are then contiguous.
        let n3 = 3 * full.len();
        let mut by_marker = vec![0.0; b * n3];
        for (i, &f) in full.iter().enumerate() {
            for (m, d) in values[f * b..(f + 1) * b].iter().enumerate() {
                by_marker[m * n3 + 3 * i..m * n3 + 3 * i + 3].copy_from_slice(&d.to_array());
            }
        }
        frame_blocks(out, v, RBF_BLOCK)
            .into_par_iter()
            .enumerate()
            .for_each(|(c, mut parts)| {
                let mut acc = vec![0.0; n3];
                let rows = &self.matrix[c * RBF_BLOCK * b..];
                add_rows_block(rows, b, &by_marker, &full, &mut parts, &mut acc);
            });
        Ok(())
    }

    /// Interpolates marker values (B; NaN rows are missing markers, refitted without them) to
    /// the V points.
    pub fn interpolate(&self, values: &[DVec3]) -> Result<Vec<DVec3>> {
        let b = self.samples.len();
        if values.len() != b {
            return Err(LgiError::Input(format!(
                "expected {b} marker values, got {}",
                values.len()
            )));
        }
        if let Some(i) = first_unreadable(values) {
            return Err(LgiError::Input(format!(
                "marker value {i} is infinite or partly NaN"
            )));
        }
        let present: Vec<bool> = values.iter().map(|p| p.is_finite()).collect();
        if present.iter().all(|&p| p) {
            return Ok(self
                .matrix
                .par_chunks(b)
                .map(|row| {
                    row.iter()
                        .zip(values)
                        .fold(DVec3::ZERO, |acc, (w, d)| acc + *d * *w)
                })
                .collect());
        }
        let lu = self.lu_for(&present)?;
        let idx: Vec<usize> = (0..b).filter(|&i| present[i]).collect();
        let mut rhs: Vec<[f64; 3]> = idx.iter().map(|&i| values[i].to_array()).collect();
        rhs.extend([[0.0; 3]; 4]);
        let coef: Vec<DVec3> = lu.solve3(&rhs).into_iter().map(DVec3::from_array).collect();
        let n = idx.len();
        Ok(self
            .points
            .par_iter()
            .map(|&p| {
                let mut acc = coef[n] + coef[n + 1] * p.x + coef[n + 2] * p.y + coef[n + 3] * p.z;
                for (k, &j) in idx.iter().enumerate() {
                    acc += coef[k] * kernel(p, self.centres[j]);
                }
                acc
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rnd(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    fn cloud(n: usize, seed: u64) -> Vec<DVec3> {
        let mut s = seed;
        (0..n)
            .map(|_| DVec3::new(rnd(&mut s), rnd(&mut s), rnd(&mut s)))
            .collect()
    }

    fn barycentric_samples(b: usize, v: usize, seed: u64) -> Vec<Sample> {
        let mut s = seed;
        (0..b)
            .map(|i| {
                let (u, w) = (rnd(&mut s), rnd(&mut s));
                let (u, w) = if u + w > 1.0 {
                    (1.0 - u, 1.0 - w)
                } else {
                    (u, w)
                };
                let j = (3 * i) as u32 % v as u32;
                ([j, j + 1, j + 2], [1.0 - u - w, u, w])
            })
            .collect()
    }

    #[test]
    fn frames_interpolated_together_add_each_frames_own_interpolation_bit_for_bit() {
        // 602 points (three blocks, the last not a whole number of tiles), 9 markers, 7
        // frames: two whole, one with a marker missing, four whole again (18 values a point:
        // a tile of 12 and 6 after it).
        let (v, b, f) = (602usize, 9usize, 7usize);
        let rbf = RbfInterpolator::new(cloud(v, 3), barycentric_samples(b, v, 4)).unwrap();
        let mut values: Vec<DVec3> = cloud(f * b, 5);
        values[2 * b + 4] = DVec3::NAN;
        let start = cloud(f * v, 6);
        let bits = |x: &[DVec3]| -> Vec<[u64; 3]> {
            x.iter().map(|p| p.to_array().map(f64::to_bits)).collect()
        };
        let (together, baseline) = crate::simd::both_builds(|| {
            let mut out = start.clone();
            rbf.add_interpolated_frames(&values, &mut out).unwrap();
            bits(&out)
        });
        assert_eq!(together, baseline);
        for k in 0..f {
            let c = rbf.interpolate(&values[k * b..(k + 1) * b]).unwrap();
            let want: Vec<DVec3> = start[k * v..(k + 1) * v]
                .iter()
                .zip(c)
                .map(|(p, c)| *p + c)
                .collect();
            assert_eq!(bits(&want), together[k * v..(k + 1) * v], "frame {k}");
        }
        let mut out = start.clone();
        let e = rbf
            .add_interpolated_frames(&values[1..], &mut out)
            .unwrap_err();
        assert!(e.to_string().contains("marker values"), "{e}");
        values[b + 1].y = f64::INFINITY;
        let e = rbf.add_interpolated_frames(&values, &mut out).unwrap_err();
        assert!(e.to_string().contains("frame 1: marker value 1"), "{e}");
    }

    #[test]
    fn interpolated_field_reproduces_every_sampled_marker_value() {
        let pts = cloud(60, 1);
        let samples = barycentric_samples(12, 60, 2);
        let rbf = RbfInterpolator::new(pts, samples.clone()).unwrap();
        let vals = cloud(12, 3);
        let out = rbf.interpolate(&vals).unwrap();
        for ((vs, ws), want) in samples.iter().zip(&vals) {
            let got = vs
                .iter()
                .zip(ws)
                .fold(DVec3::ZERO, |a, (&v, &w)| a + out[v as usize] * w);
            assert!((got - *want).length() < 1e-9, "{got} vs {want}");
        }
    }

    #[test]
    fn linear_fields_are_reproduced_exactly_everywhere() {
        let pts = cloud(50, 4);
        let rbf = RbfInterpolator::new(pts.clone(), barycentric_samples(10, 50, 5)).unwrap();
        let f = |p: DVec3| DVec3::new(2.0 * p.x - p.y + 0.5, p.z, 3.0 * p.y - 1.0);
        let vals: Vec<DVec3> = rbf.centres().iter().map(|&c| f(c)).collect();
        for (p, got) in pts.iter().zip(rbf.interpolate(&vals).unwrap()) {
            assert!((got - f(*p)).length() < 1e-9);
        }
    }

    #[test]
    fn missing_markers_refit_equals_a_fresh_fit_without_them() {
        let pts = cloud(40, 6);
        let samples = barycentric_samples(10, 40, 7);
        let rbf = RbfInterpolator::new(pts.clone(), samples.clone()).unwrap();
        let mut vals = cloud(10, 8);
        vals[3] = DVec3::NAN;
        let got = rbf.interpolate(&vals).unwrap();
        let keep: Vec<usize> = (0..10).filter(|&i| i != 3).collect();
        let fresh = RbfInterpolator::new(pts, keep.iter().map(|&i| samples[i]).collect()).unwrap();
        let want = fresh
            .interpolate(&keep.iter().map(|&i| vals[i]).collect::<Vec<_>>())
            .unwrap();
        for (a, b) in got.iter().zip(&want) {
            assert!((*a - *b).length() < 1e-9);
        }
    }

    #[test]
    fn coplanar_markers_and_bad_inputs_are_input_errors() {
        let pts: Vec<DVec3> = (0..20)
            .map(|i| DVec3::new(i as f64, (i * i % 7) as f64, 0.0))
            .collect();
        let samples: Vec<Sample> = (0..6).map(|i| ([i, i, i], [1.0, 0.0, 0.0])).collect();
        assert!(matches!(
            RbfInterpolator::new(pts.clone(), samples),
            Err(LgiError::Input(_))
        ));
        let few: Vec<Sample> = (0..3).map(|i| ([i, i, i], [1.0, 0.0, 0.0])).collect();
        assert!(RbfInterpolator::new(pts.clone(), few).is_err());
        let bad: Vec<Sample> = (0..5).map(|i| ([i, 99, i], [1.0, 0.0, 0.0])).collect();
        assert!(RbfInterpolator::new(pts, bad).is_err());
    }
}

/// Points and values per tile of [`add_rows_block`]: 4 points × 12 values (four frames'
/// x, y, z) of sums kept in registers while the block's rows pass, each value of the markers
/// read once for four points and each matrix entry once for twelve values.
const TILE_POINTS: usize = 4;
const TILE_VALUES: usize = 12;

with_avx2! {
/// One block of [`RbfInterpolator::add_interpolated_frames`]: for each point of the block (a
/// row of `rows`, `b` wide), every present frame's `Σ_m row[m] values[m]` summed from 0 with
/// markers ascending (the bits of `interpolate`'s fold), added to frame `full[i]`'s point in
/// `parts`; `acc` holds a point's sums (3 per frame). Tiles of points and values side by
/// side where they fit, each sum in the same order.
fn add_rows_block(
    rows: &[f64],
    b: usize,
    by_marker: &[f64],
    full: &[usize],
    parts: &mut [&mut [DVec3]],
    acc: &mut [f64],
) {
    let n3 = acc.len();
    let len = parts.first().map_or(0, |p| p.len());
    let tiled_points = len - len % TILE_POINTS;
    let tiled_values = n3 - n3 % TILE_VALUES;
    for k0 in (0..tiled_points).step_by(TILE_POINTS) {
        for c0 in (0..tiled_values).step_by(TILE_VALUES) {
            let mut t = [[0.0f64; TILE_VALUES]; TILE_POINTS];
            for m in 0..b {
                let x = &by_marker[m * n3 + c0..m * n3 + c0 + TILE_VALUES];
                for (i, ti) in t.iter_mut().enumerate() {
                    let w = rows[(k0 + i) * b + m];
                    for (a, x) in ti.iter_mut().zip(x) {
                        *a += *x * w;
                    }
                }
            }
            for (i, ti) in t.iter().enumerate() {
                for (j, &sum) in ti.iter().enumerate() {
                    let c = c0 + j;
                    parts[full[c / 3]][k0 + i][c % 3] += sum;
                }
            }
        }
    }
    // What the tiles leave: the last values of the tiled points, then the last points whole.
    let mut add = |k: usize, from: usize, acc: &mut [f64]| {
        acc[from..].iter_mut().for_each(|a| *a = 0.0);
        for (m, &w) in rows[k * b..(k + 1) * b].iter().enumerate() {
            for (a, x) in acc[from..].iter_mut().zip(&by_marker[m * n3 + from..(m + 1) * n3]) {
                *a += *x * w;
            }
        }
        for (c, &sum) in acc.iter().enumerate().skip(from) {
            parts[full[c / 3]][k][c % 3] += sum;
        }
    };
    if tiled_values < n3 {
        for k in 0..tiled_points {
            add(k, tiled_values, acc);
        }
    }
    for k in tiled_points..len {
        add(k, 0, acc);
    }
}
}
