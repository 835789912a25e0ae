//! Shared fixtures for the criterion benches: the workload (dataset, markers, frames) that every
//! bench measures, so that stage timings are comparable. ICT-300 when the ICT-FaceKit data is
//! present; otherwise a procedural face-like surface so `cargo bench` runs on a fresh clone.

use glam::{DVec2, DVec3};
use lgi_core::{
    BuildConfig, Dataset, FrameInfo, FrameState, LgiError, Mesh, Model, Result, SolveOptions,
};
use std::path::{Path, PathBuf};

/// Frames in the default workload.
pub const NUM_FRAMES: usize = 500;
/// Shapes the ICT dataset is augmented to.
pub const ICT_SHAPES: usize = 300;
/// Standard deviation of the marker noise (data units: cm for ICT).
pub const MARKER_NOISE: f64 = 0.05;

/// What a bench measures: a dataset, its markers and a sequence of frames (bundle targets).
pub struct Workload {
    /// Human-readable description (printed by the benches).
    pub name: String,
    /// The dataset the model is built from.
    pub dataset: Dataset,
    /// Marker rest positions (B).
    pub markers: Vec<DVec3>,
}

/// A small deterministic RNG (xorshift64*): the benches need reproducible, not good, numbers.
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed (any value; zero is remapped).
    pub fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform integer in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.uniform() * n as f64) as usize % n.max(1)
    }
    /// Approximately standard normal (sum of 12 uniforms; enough for noise).
    pub fn gaussian(&mut self) -> f64 {
        (0..12).map(|_| self.uniform()).sum::<f64>() - 6.0
    }
}

/// Root of the shared data: `$LGI_SHARED_DATA`, else `../../shared/data` from this crate, or
/// the first `shared/data` holding ICT above it (git worktrees sit deeper than the checkout).
pub fn shared_data() -> PathBuf {
    if let Some(d) = std::env::var_os("LGI_SHARED_DATA") {
        return PathBuf::from(d);
    }
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    here.ancestors()
        .map(|a| a.join("shared/data"))
        .find(|d| d.join("ict-facekit/generic_neutral_mesh.obj").is_file())
        .unwrap_or_else(|| here.join("../../shared/data"))
}

/// Loads ICT-300 when the data is present, else the procedural workload. Prints which.
pub fn load_workload() -> Result<Workload> {
    let ict = shared_data().join("ict-facekit");
    let w = if ict.join("generic_neutral_mesh.obj").is_file() {
        load_ict(&ict)?
    } else {
        procedural()?
    };
    eprintln!("lgi-benches workload: {}", w.name);
    Ok(w)
}

/// ICT neutral + its shapes, augmented to [`ICT_SHAPES`], with markers_120.
pub fn load_ict(dir: &Path) -> Result<Workload> {
    let shape_dir = dir.join("shapes");
    let mut shapes: Vec<PathBuf> = std::fs::read_dir(&shape_dir)
        .map_err(|e| io_error(&shape_dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "obj"))
        .collect();
    shapes.sort();
    let base = Dataset::from_obj_files(&dir.join("generic_neutral_mesh.obj"), &shapes)?;
    let dataset = lgi_core::augment(&base, ICT_SHAPES)?;
    let markers = read_markers(&dir.join("markers_120.csv"))?;
    Ok(Workload {
        name: format!(
            "ICT-{ICT_SHAPES}: ICT-FaceKit neutral ({} vertices) + {} shapes augmented to {}, {} markers",
            dataset.num_vertices(),
            base.num_shapes(),
            dataset.num_shapes(),
            markers.len()
        ),
        dataset,
        markers,
    })
}

fn io_error(path: &Path, e: std::io::Error) -> LgiError {
    LgiError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// Reads a `name,x,y,z` CSV with a header line.
pub fn read_markers(path: &Path) -> Result<Vec<DVec3>> {
    let text = std::fs::read_to_string(path).map_err(|e| io_error(path, e))?;
    let mut out = Vec::new();
    for (line_no, line) in text.lines().enumerate().skip(1) {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').collect();
        let parse = |s: Option<&&str>| -> Result<f64> {
            s.and_then(|s| s.trim().parse::<f64>().ok())
                .ok_or_else(|| LgiError::Parse {
                    path: path.to_path_buf(),
                    line: line_no + 1,
                    message: "expected name,x,y,z".into(),
                })
        };
        out.push(DVec3::new(
            parse(f.get(1))?,
            parse(f.get(2))?,
            parse(f.get(3))?,
        ));
    }
    Ok(out)
}

/// A face-like parametric surface (~10k vertices, UVs), ~40 smooth and wrinkle shapes, ~100
/// markers. Not a face, but the same sizes and a smooth-plus-fine-detail shape mix.
pub fn procedural() -> Result<Workload> {
    let (nu, nv) = (100usize, 100usize);
    let mut positions = Vec::with_capacity(nu * nv);
    let mut uvs = Vec::with_capacity(nu * nv);
    let surface = |u: f64, v: f64| {
        let x = (u - 0.5) * 14.0;
        let y = (v - 0.5) * 18.0;
        let z = 6.0 * (1.0 - (x / 9.0).powi(2) - (y / 12.0).powi(2))
            + 1.5 * (-(x * x + (y - 1.0).powi(2)) / 4.0).exp();
        DVec3::new(x, y, z)
    };
    for j in 0..nv {
        for i in 0..nu {
            let (u, v) = (i as f64 / (nu - 1) as f64, j as f64 / (nv - 1) as f64);
            positions.push(surface(u, v));
            uvs.push(DVec2::new(u, v));
        }
    }
    let mut triangles = Vec::new();
    for j in 0..nv - 1 {
        for i in 0..nu - 1 {
            let a = (j * nu + i) as u32;
            let (b, c, d) = (a + 1, a + nu as u32, a + nu as u32 + 1);
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
    }
    let mesh = Mesh {
        positions: positions.clone(),
        uv_triangles: triangles.clone(),
        triangles,
        uvs: uvs.clone(),
    };
    let mut rng = Rng::new(7);
    let mut shapes = Vec::new();
    for k in 0..40 {
        let c = DVec2::new(0.15 + 0.7 * rng.uniform(), 0.15 + 0.7 * rng.uniform());
        let radius = 0.08 + 0.15 * rng.uniform();
        let dir = DVec3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()).normalize_or_zero();
        let amp = 0.5 + rng.uniform();
        let wrinkle = k % 2 == 1;
        let freq = 30.0 + 30.0 * rng.uniform();
        let shape: Vec<DVec3> = uvs
            .iter()
            .zip(&positions)
            .map(|(uv, p)| {
                let r2 = uv.distance_squared(c) / (radius * radius);
                let bump = (-r2).exp();
                let mut d = dir * amp * bump;
                if wrinkle {
                    d += DVec3::Z * 0.1 * bump * (freq * (uv.x - c.x)).sin();
                }
                *p + d
            })
            .collect();
        shapes.push((format!("shape{k:02}"), shape));
    }
    let dataset = Dataset::from_shape_positions(mesh, shapes)?;
    let mut markers = Vec::new();
    for j in 0..10 {
        for i in 0..10 {
            let u = 0.08 + 0.84 * (i as f64 + 0.3 * rng.uniform()) / 9.3;
            let v = 0.08 + 0.84 * (j as f64 + 0.3 * rng.uniform()) / 9.3;
            markers.push(surface(u, v));
        }
    }
    Ok(Workload {
        name: format!(
            "procedural: parametric surface ({} vertices) + {} shapes, {} markers (ICT data not found)",
            dataset.num_vertices(),
            dataset.num_shapes(),
            markers.len()
        ),
        dataset,
        markers,
    })
}

/// Builds the model with the default configuration.
pub fn build_model(w: &Workload) -> Result<Model> {
    Model::build(&w.dataset, &w.markers, &BuildConfig::default())
}

/// One frame solved the paper's way ([`SolveOptions::default`]) after `previous` (a temporal
/// solve's state), its vertices into `out` (V): what a frame-by-frame caller of
/// [`Model::solve`] does.
pub fn solve_frame(
    model: &Model,
    targets: &[DVec3],
    previous: Option<&FrameState>,
    out: &mut [DVec3],
) -> Result<FrameInfo> {
    let frames = [targets.to_vec()];
    let mut infos = model.solve(&frames, &SolveOptions::default(), previous, out, |_| {})?;
    infos
        .pop()
        .ok_or_else(|| LgiError::Input("a one-frame solve returned no frame".into()))
}

/// `n` frames: bundle positions of seeded random convex combinations of 1–4 dataset shapes,
/// plus Gaussian marker noise of [`MARKER_NOISE`] (so some targets fall outside every tet).
pub fn make_frames(model: &Model, n: usize, seed: u64) -> Result<Vec<Vec<DVec3>>> {
    let d = model.dataset();
    let x0 = &d.neutral().positions;
    let s = d.num_shapes();
    let mut rng = Rng::new(seed);
    let mut frames = Vec::with_capacity(n);
    let mut mesh = x0.clone();
    for _ in 0..n {
        let m = 1 + rng.below(4);
        let ks: Vec<usize> = (0..m).map(|_| rng.below(s)).collect();
        let mut w: Vec<f64> = (0..m).map(|_| rng.uniform() + 1e-3).collect();
        let total: f64 = w.iter().sum();
        w.iter_mut().for_each(|x| *x /= total);
        mesh.copy_from_slice(x0);
        for (&k, &wk) in ks.iter().zip(&w) {
            for (v, p) in mesh.iter_mut().enumerate() {
                *p += d.displacement(k, v) * wk;
            }
        }
        let mut targets = model.bundle_positions(&mesh)?;
        for t in &mut targets {
            *t += DVec3::new(rng.gaussian(), rng.gaussian(), rng.gaussian()) * MARKER_NOISE;
        }
        frames.push(targets);
    }
    Ok(frames)
}

/// This process's user + system CPU time in seconds (Linux `/proc/self/stat`, 10 ms ticks).
pub fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which may hold spaces) start at state (field 3).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<f64> = rest
        .split_whitespace()
        .skip(11)
        .take(2)
        .filter_map(|x| x.parse().ok())
        .collect();
    f.iter().sum::<f64>() / 100.0
}

/// The middle value (upper median); NaN for none.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n => v[n / 2],
    }
}

/// The dropout examples' settings: the fraction of markers missing (first argument, default
/// 10 %) and the passes (`LGI_PASSES`, else `default_passes`).
pub fn dropout_settings(default_passes: usize) -> (f64, usize) {
    let fraction = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(0.1);
    let passes = std::env::var("LGI_PASSES")
        .ok()
        .and_then(|p| p.parse().ok())
        .unwrap_or(default_passes);
    (fraction, passes)
}

/// `frames` with each target missing (NaN) with probability `fraction`: a fresh random set
/// on every frame.
pub fn with_dropouts(frames: &[Vec<DVec3>], fraction: f64, rng: &mut Rng) -> Vec<Vec<DVec3>> {
    frames
        .iter()
        .map(|f| {
            f.iter()
                .map(|&t| match rng.uniform() < fraction {
                    true => DVec3::NAN,
                    false => t,
                })
                .collect()
        })
        .collect()
}
