//! Correspondences on the real ICT FaceKit neutral: every marker's BVH answer equals brute force
//! over all triangles, plus random queries; skipped when the data is absent. The OBJ parser here
//! is deliberately minimal (v and f lines only) so this test does not depend on the io module.

use lgi_core::{closest_point_on_triangle, correspond, DVec3, Mesh, SurfaceIndex, SurfacePoint};
mod common;

use std::path::PathBuf;
use std::time::Instant;

/// The ICT data (see `common::ict_dir`), saying why when it is skipped.
fn data_dir() -> Option<PathBuf> {
    let found = common::ict_dir();
    if found.is_none() {
        eprintln!("skipping: ICT data not found (set LGI_SHARED_DATA or put it in ../shared/data)");
    }
    found
}

/// `v` and `f` lines only; polygons are fan-split; `f` corners may be `i`, `i/t`, `i/t/n`.
fn read_obj(path: &std::path::Path) -> Mesh {
    let text = std::fs::read_to_string(path).unwrap();
    let mut mesh = Mesh::default();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|s| s.parse().unwrap()).collect();
                mesh.positions.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("f") => {
                let idx: Vec<u32> = it
                    .map(|s| s.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
                    .collect();
                for k in 1..idx.len() - 1 {
                    mesh.triangles.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            _ => {}
        }
    }
    mesh
}

fn read_markers(path: &std::path::Path) -> Vec<DVec3> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    assert_eq!(lines.next().unwrap().trim(), "name,x,y,z");
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let c: Vec<f64> = l.split(',').skip(1).map(|s| s.parse().unwrap()).collect();
            DVec3::new(c[0], c[1], c[2])
        })
        .collect()
}

fn brute_force(mesh: &Mesh, p: DVec3) -> (SurfacePoint, f64) {
    let mut best = (u32::MAX, f64::INFINITY, [0.0; 3]);
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.triangle(t);
        let (q, bary) = closest_point_on_triangle(p, a, b, c);
        let d2 = p.distance_squared(q);
        if d2 < best.1 {
            best = (t as u32, d2, bary);
        }
    }
    (
        SurfacePoint {
            triangle: best.0,
            bary: best.2,
        },
        best.1.sqrt(),
    )
}

/// Deterministic uniform points in the mesh's bounding box grown by 20%.
fn random_points(mesh: &Mesh, n: usize, seed: u64) -> Vec<DVec3> {
    let (lo, hi) = mesh.bounds();
    let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.6);
    let mut s = seed;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    (0..n)
        .map(|_| c + h * DVec3::new(next(), next(), next()))
        .collect()
}

#[test]
fn ict_markers_and_random_points_match_brute_force() {
    let Some(dir) = data_dir() else { return };
    let mesh = read_obj(&dir.join("generic_neutral_mesh.obj"));
    let markers = read_markers(&dir.join("markers_120.csv"));
    assert_eq!(markers.len(), 120);

    let t0 = Instant::now();
    let index = SurfaceIndex::new(&mesh).unwrap();
    let build = t0.elapsed();
    let t1 = Instant::now();
    let found = index.closest_many(&markers);
    let query = t1.elapsed();

    let mut max_d: f64 = 0.0;
    for (p, got) in markers.iter().zip(&found) {
        let want = brute_force(&mesh, *p);
        assert_eq!(got.0, want.0, "marker at {p:?}");
        assert!((got.1 - want.1).abs() <= 1e-12 * want.1.max(1e-300));
        max_d = max_d.max(got.1);
    }
    // correspond() agrees with the index and accepts the markers at a tolerance just above max.
    let via = correspond(&mesh, &markers, max_d * 1.000_001 + 1e-12).unwrap();
    assert_eq!(via, found);
    eprintln!(
        "ICT: {} triangles, BVH build {:.2?}, 120 markers {:.2?}, max marker distance {:.3e} (diag {:.3})",
        mesh.triangles.len(),
        build,
        query,
        max_d,
        mesh.diagonal()
    );

    for p in random_points(&mesh, 50, 7) {
        let want = brute_force(&mesh, p);
        let got = index.closest(p);
        assert_eq!(got.0, want.0, "random point {p:?}");
        assert!((got.1 - want.1).abs() <= 1e-12 * want.1.max(1e-300));
    }
}

/// Timing only (no reference), run with
/// `cargo test --release -p lgi-core --test correspond_random -- --ignored --nocapture`.
#[test]
#[ignore]
fn ict_timing_build_and_100k_queries() {
    let Some(dir) = data_dir() else { return };
    let mesh = read_obj(&dir.join("generic_neutral_mesh.obj"));
    let markers = read_markers(&dir.join("markers_120.csv"));
    let points = random_points(&mesh, 100_000, 11);
    for _ in 0..3 {
        let t0 = Instant::now();
        let index = SurfaceIndex::new(&mesh).unwrap();
        let build = t0.elapsed();
        let t1 = Instant::now();
        let m = index.closest_many(&markers);
        let tm = t1.elapsed();
        let t2 = Instant::now();
        let r = index.closest_many(&points);
        let tp = t2.elapsed();
        let t3 = Instant::now();
        let serial: Vec<_> = points[..20_000].iter().map(|p| index.closest(*p)).collect();
        let ts = t3.elapsed();
        assert_eq!(m.len() + r.len() + serial.len(), 120 + 100_000 + 20_000);
        eprintln!(
            "build {build:.2?} | 120 markers {tm:.2?} | 100k random (rayon, {} threads) {tp:.2?} | 20k serial {ts:.2?} ({:.2} us/query)",
            rayon::current_num_threads(),
            ts.as_secs_f64() * 1e6 / 20_000.0
        );
    }
}
