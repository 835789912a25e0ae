//! A take's frames with some marker rows missing, each filled by the frame's own fit, in the
//! fit matrix's own coordinates (`A = U S Vᵀ`, a frame `ζ = Uᵀ d / σ`): what the take prior's
//! reading (python/lgi/plan/take_prior.py) does to every frame short of a row, once per
//! left-out marker (the held-out priors), several rounds each. A frame's m missing rows cost
//! products with those m rows of U and an m × m solve (Woodbury's identity), not products
//! with all R rows, which is most of a take prior's reading when done for every frame in
//! numpy.

use crate::error::{LgiError, Result};
use crate::linalg::{cholesky, cholesky_solve, dot8};

/// The frames of a take short of a row, and each one's missing rows (in row order).
#[derive(Debug, Clone, PartialEq)]
pub struct MissingRows {
    rows: usize,
    frames: Vec<usize>,
    starts: Vec<usize>,
    missing: Vec<usize>,
}

impl MissingRows {
    /// From `present` (F × R, row-major): which of each frame's R rows are present.
    pub fn of(present: &[bool], rows: usize) -> Result<MissingRows> {
        if rows == 0 || present.len() % rows != 0 {
            return Err(LgiError::Input(format!(
                "missing rows: {} flags are not whole frames of {rows} rows",
                present.len()
            )));
        }
        let mut out = MissingRows {
            rows,
            frames: Vec::new(),
            starts: vec![0],
            missing: Vec::new(),
        };
        for (f, frame) in present.chunks_exact(rows).enumerate() {
            let before = out.missing.len();
            out.missing.extend(
                frame
                    .iter()
                    .enumerate()
                    .filter(|(_, &p)| !p)
                    .map(|(r, _)| r),
            );
            if out.missing.len() > before {
                out.frames.push(f);
                out.starts.push(out.missing.len());
            }
        }
        Ok(out)
    }

    /// How many frames are short of a row.
    pub fn num_frames(&self) -> usize {
        self.frames.len()
    }

    /// Each frame short of a row, with its missing rows.
    fn each(&self) -> impl Iterator<Item = (usize, &[usize])> {
        self.frames
            .iter()
            .zip(self.starts.windows(2))
            .map(|(&f, w)| (f, &self.missing[w[0]..w[1]]))
    }
}

/// Row `i` of a row-major matrix of `q` columns.
fn row(m: &[f64], i: usize, q: usize) -> &[f64] {
    &m[i * q..(i + 1) * q]
}

/// The fit's coordinates as the fills read them: `u` (R × q, row-major, orthonormal columns),
/// a left factor `l` (R × q) and `k = l Uᵀ` (R × R), of a frame fit whose missing rows' values
/// are `U_M fitted`, with `fitted = y + U_Mᵀ x` and `(I - K_MM) x = L_M y` for the frame's
/// present share `y = U_Pᵀ d_P / σ`: the ridge fit (`L = U D⁻¹`, `D = I + ridge S⁻²`) or a
/// fit under a prior (`L = U P`, `P = Φ (ΦᵀΦ + I)⁻¹ Φᵀ`, the prior's mean taken off first).
#[derive(Debug, Clone, Copy)]
pub struct FillFit<'a> {
    /// U (R × q).
    pub u: &'a [f64],
    /// The fit's left factor L (R × q).
    pub l: &'a [f64],
    /// K = L Uᵀ (R × R).
    pub k: &'a [f64],
    /// q, the fit's directions.
    pub directions: usize,
}

impl FillFit<'_> {
    /// Every frame of `zeta` (F × q, row-major) short of a row (`missing`) filled by its fit:
    /// without `mean`, `zeta`'s frames are their present share and become `y + U_Mᵀ x`; with
    /// `mean`, a frame's offset from it less its missing rows' share is `y`, and the frame
    /// becomes `mean + y + U_Mᵀ x` (its fit under the prior of that mean).
    pub fn fill(
        &self,
        missing: &MissingRows,
        zeta: &mut [f64],
        mean: Option<&[f64]>,
    ) -> Result<()> {
        let (r, q) = (missing.rows, self.directions);
        let frames = zeta.len().checked_div(q).unwrap_or(0);
        if self.u.len() != r * q
            || self.l.len() != r * q
            || self.k.len() != r * r
            || zeta.len() != frames * q
            || missing.frames.last().is_some_and(|&f| f >= frames)
            || mean.is_some_and(|m| m.len() != q)
        {
            return Err(LgiError::Input(format!(
                "missing rows: u and l must be {r} x {q}, k {r} x {r}, the frames whole rows of \
                 {q} directions covering every frame short of a row, the mean {q} values"
            )));
        }
        let mut y = vec![0.0; q];
        let mut g = Vec::new();
        for (f, rows) in missing.each() {
            let frame = &mut zeta[f * q..(f + 1) * q];
            match mean {
                None => y.copy_from_slice(frame),
                Some(mean) => {
                    for ((yi, &z), &m) in y.iter_mut().zip(frame.iter()).zip(mean) {
                        *yi = z - m;
                    }
                    // The missing rows' share of the offset taken off: U_Mᵀ U_M (ζ - mean), each
                    // row's share read from the whole offset (U's rows are not orthogonal).
                    g.clear();
                    g.extend(rows.iter().map(|&i| dot8(row(self.u, i, q), &y)));
                    for (&i, &gi) in rows.iter().zip(&g) {
                        for (yi, &ui) in y.iter_mut().zip(row(self.u, i, q)) {
                            *yi -= gi * ui;
                        }
                    }
                }
            }
            let m = rows.len();
            let mut lhs = vec![0.0; m * m];
            for (a, &i) in rows.iter().enumerate() {
                for (b, &j) in rows.iter().enumerate() {
                    lhs[a * m + b] = f64::from(u8::from(a == b)) - self.k[i * r + j];
                }
            }
            let rhs: Vec<f64> = rows.iter().map(|&i| dot8(row(self.l, i, q), &y)).collect();
            // I - K_MM is symmetric positive definite: U's rows are within the unit ball and
            // both fits shrink (D⁻¹ < I, P < I).
            let factor = cholesky(m, lhs).map_err(|_| {
                LgiError::Input(format!(
                    "missing rows: frame {f}'s fit of its {m} missing rows is singular (a \
                     direction the markers do not see given no prior)"
                ))
            })?;
            let x = cholesky_solve(m, &factor, &rhs);
            for (&i, &xi) in rows.iter().zip(&x) {
                for (yi, &ui) in y.iter_mut().zip(row(self.u, i, q)) {
                    *yi += xi * ui;
                }
            }
            match mean {
                None => frame.copy_from_slice(&y),
                Some(mean) => {
                    for ((z, &yi), &m) in frame.iter_mut().zip(&y).zip(mean) {
                        *z = m + yi;
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small fit's coordinates: U (R × q) with orthonormal columns (Gram-Schmidt of a
    /// pseudo-random matrix), L = U diag(a) and K = L Uᵀ.
    fn coordinates(r: usize, q: usize, a: &[f64], seed: u64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for _ in 0..q {
            let mut c: Vec<f64> = (0..r).map(|_| rnd()).collect();
            for prev in &cols {
                let d: f64 = c.iter().zip(prev).map(|(x, y)| x * y).sum();
                c.iter_mut().zip(prev).for_each(|(x, y)| *x -= d * y);
            }
            let n = c.iter().map(|x| x * x).sum::<f64>().sqrt();
            c.iter_mut().for_each(|x| *x /= n);
            cols.push(c);
        }
        let u: Vec<f64> = (0..r * q).map(|i| cols[i % q][i / q]).collect();
        let l: Vec<f64> = (0..r * q).map(|i| u[i] * a[i % q]).collect();
        let k: Vec<f64> = (0..r * r)
            .map(|i| {
                (0..q)
                    .map(|j| l[(i / r) * q + j] * u[(i % r) * q + j])
                    .sum()
            })
            .collect();
        (u, l, k)
    }

    #[test]
    fn a_ridge_fill_is_the_frames_ridge_fit_of_its_present_rows() {
        // Reference: the frame's ridge fit solved directly, min |U_P z - d_P|² + zᵀ(D - I)z
        // with D = diag(1 / a): (U_PᵀU_P + D - I) z = U_Pᵀ d_P, and ζ = U_Pᵀ d_P + U_Mᵀ U_M z.
        let (r, q) = (12, 4);
        let a = [0.9, 0.7, 0.5, 0.2];
        let (u, l, k) = coordinates(r, q, &a, 3);
        let d: Vec<f64> = (0..r).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut present = vec![true; r];
        for &i in &[1, 5, 6] {
            present[i] = false;
        }
        let y: Vec<f64> = (0..q)
            .map(|j| {
                (0..r)
                    .filter(|&i| present[i])
                    .map(|i| u[i * q + j] * d[i])
                    .sum()
            })
            .collect();
        let mut gram = vec![0.0; q * q];
        for j in 0..q {
            for c in 0..q {
                let upu: f64 = (0..r)
                    .filter(|&i| present[i])
                    .map(|i| u[i * q + j] * u[i * q + c])
                    .sum();
                gram[j * q + c] = upu + if j == c { 1.0 / a[j] - 1.0 } else { 0.0 };
            }
        }
        let z = cholesky_solve(q, &cholesky(q, gram).unwrap(), &y);
        let want: Vec<f64> = (0..q)
            .map(|j| {
                y[j] + (0..r)
                    .filter(|&i| !present[i])
                    .map(|i| u[i * q + j] * (0..q).map(|c| u[i * q + c] * z[c]).sum::<f64>())
                    .sum::<f64>()
            })
            .collect();
        let missing = MissingRows::of(&present, r).unwrap();
        let mut zeta = y.clone();
        let fit = FillFit {
            u: &u,
            l: &l,
            k: &k,
            directions: q,
        };
        fit.fill(&missing, &mut zeta, None).unwrap();
        for (g, w) in zeta.iter().zip(&want) {
            assert!((g - w).abs() < 1e-12, "{g} vs {w}");
        }
    }

    #[test]
    fn a_whole_frame_is_left_as_it_is_and_a_frame_beyond_the_take_is_refused() {
        let (r, q) = (6, 2);
        let (u, l, k) = coordinates(r, q, &[0.5, 0.5], 1);
        let fit = FillFit {
            u: &u,
            l: &l,
            k: &k,
            directions: q,
        };
        let mut present = vec![true; 2 * r];
        present[r + 2] = false;
        let missing = MissingRows::of(&present, r).unwrap();
        assert_eq!(missing.num_frames(), 1);
        let mut zeta = vec![0.3, -0.2, 0.1, 0.4];
        fit.fill(&missing, &mut zeta, Some(&[0.0, 0.0])).unwrap();
        assert_eq!(&zeta[..2], &[0.3, -0.2]);
        assert_ne!(&zeta[2..], &[0.1, 0.4]);
        let mut short = vec![0.0; q];
        assert!(fit.fill(&missing, &mut short, None).is_err());
        assert!(MissingRows::of(&present[..7], r).is_err());
    }

    #[test]
    fn a_fill_under_a_prior_is_the_dense_woodbury_fill() {
        // Reference, with the frame's missing rows of U as whole rows: g = U_M (ζ - mean),
        // r = (ζ - mean) - U_Mᵀ g, t = (I - L_M U_Mᵀ)⁻¹ L_M r (Gaussian elimination) and the
        // frame ζ - U_Mᵀ (g - t).
        let (r, q) = (10, 4);
        let (u, l, k) = coordinates(r, q, &[0.8, 0.6, 0.3, 0.1], 11);
        let rows = [2usize, 3, 7];
        let mut present = vec![true; r];
        rows.iter().for_each(|&i| present[i] = false);
        let zeta = [0.4, -1.2, 0.7, 2.0];
        let mean = [0.1, 0.2, -0.3, 0.5];
        let d: Vec<f64> = zeta.iter().zip(&mean).map(|(z, m)| z - m).collect();
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let urow = |i: usize| &u[i * q..(i + 1) * q];
        let lrow = |i: usize| &l[i * q..(i + 1) * q];
        let g: Vec<f64> = rows.iter().map(|&i| dot(urow(i), &d)).collect();
        let mut res = d.clone();
        for (&i, gi) in rows.iter().zip(&g) {
            res.iter_mut()
                .zip(urow(i))
                .for_each(|(x, ui)| *x -= gi * ui);
        }
        let m = rows.len();
        let mut a: Vec<Vec<f64>> = rows
            .iter()
            .enumerate()
            .map(|(ai, &i)| {
                let mut line: Vec<f64> = (0..m)
                    .map(|bi| f64::from(u8::from(ai == bi)) - dot(lrow(i), urow(rows[bi])))
                    .collect();
                line.push(dot(lrow(i), &res));
                line
            })
            .collect();
        for c in 0..m {
            for rr in (c + 1)..m {
                let f = a[rr][c] / a[c][c];
                let pivot = a[c].clone();
                a[rr].iter_mut().zip(&pivot).for_each(|(x, p)| *x -= f * p);
            }
        }
        let mut t = vec![0.0; m];
        for c in (0..m).rev() {
            let s: f64 = ((c + 1)..m).map(|j| a[c][j] * t[j]).sum();
            t[c] = (a[c][m] - s) / a[c][c];
        }
        let mut want = zeta.to_vec();
        for ((&i, gi), ti) in rows.iter().zip(&g).zip(&t) {
            want.iter_mut()
                .zip(urow(i))
                .for_each(|(x, ui)| *x -= (gi - ti) * ui);
        }
        let missing = MissingRows::of(&present, r).unwrap();
        let mut got = zeta.to_vec();
        let fit = FillFit {
            u: &u,
            l: &l,
            k: &k,
            directions: q,
        };
        fit.fill(&missing, &mut got, Some(&mean)).unwrap();
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() < 1e-12, "{g} vs {w}");
        }
    }

    #[test]
    fn a_fill_under_a_mean_with_nothing_missing_beyond_it_keeps_the_mean_offset() {
        // With the prior's mean at the frame itself, the offset is 0 and so is every fill.
        let (r, q) = (8, 3);
        let (u, l, k) = coordinates(r, q, &[0.6, 0.4, 0.3], 7);
        let fit = FillFit {
            u: &u,
            l: &l,
            k: &k,
            directions: q,
        };
        let mut present = vec![true; r];
        present[0] = false;
        present[3] = false;
        let missing = MissingRows::of(&present, r).unwrap();
        let mean = [0.25, -0.5, 1.0];
        let mut zeta = mean.to_vec();
        fit.fill(&missing, &mut zeta, Some(&mean)).unwrap();
        for (z, m) in zeta.iter().zip(&mean) {
            assert!((z - m).abs() < 1e-15);
        }
    }
}
