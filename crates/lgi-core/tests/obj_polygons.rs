//! The OBJ reader's source faces against the faces written: random polygon meshes (3 to 7
//! corners, random vertex and UV indices, 1-based or negative) rendered as OBJ text read back
//! as exactly the faces written, fan-splitting into exactly the triangles, and surviving a
//! dataset's save and load.

use lgi_core::{read_obj_polygons, BuildConfig, DVec3, Dataset, Model, Polygons};
use proptest::prelude::*;

/// A face: distinct vertex indices (< `nv`), UV indices (< `nt`).
fn faces(nv: usize, nt: usize) -> impl Strategy<Value = Vec<(Vec<u32>, Vec<u32>)>> {
    let face = (3usize..8).prop_flat_map(move |n| {
        (
            proptest::sample::subsequence((0..nv as u32).collect::<Vec<_>>(), n).prop_shuffle(),
            proptest::collection::vec(0..nt as u32, n),
        )
    });
    proptest::collection::vec(face, 1..40)
}

fn obj_text(nv: usize, nt: usize, faces: &[(Vec<u32>, Vec<u32>)], relative: bool) -> String {
    let mut s = String::new();
    for i in 0..nv {
        s += &format!(
            "v {} {} {}\n",
            i as f64,
            (i * i) as f64 * 0.1,
            (i % 3) as f64
        );
    }
    for i in 0..nt {
        s += &format!("vt {} {}\n", i as f64 / nt as f64, 0.5);
    }
    for (v, t) in faces {
        s += "f";
        for (a, b) in v.iter().zip(t) {
            if relative {
                s += &format!(" -{}/-{}", nv as u32 - a, nt as u32 - b);
            } else {
                s += &format!(" {}/{}", a + 1, b + 1);
            }
        }
        s += "\n";
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 64,
        rng_seed: proptest::test_runner::RngSeed::Fixed(16),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn source_faces_read_back_as_written_and_fan_split_into_the_triangles(
        fs in faces(12, 9),
        relative in any::<bool>(),
    ) {
        let dir = std::env::temp_dir().join(format!("lgi-polys-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("m{relative}.obj"));
        std::fs::write(&path, obj_text(12, 9, &fs, relative)).unwrap();
        let (mesh, polys) = read_obj_polygons(&path).unwrap();
        let mut want = Polygons::default();
        for (v, t) in &fs {
            want.push(v, Some(t));
        }
        prop_assert_eq!(&polys, &want);
        // Brute-force fan split, written out independently of the reader.
        let mut tris = Vec::new();
        for (v, _) in &fs {
            for k in 1..v.len() - 1 {
                tris.push([v[0], v[k], v[k + 1]]);
            }
        }
        prop_assert_eq!(&mesh.triangles, &tris);
        prop_assert!(polys.check_against(&mesh, "m").is_ok());
    }
}

#[test]
fn an_obj_datasets_polygons_survive_a_saved_model() {
    // A 4x4 grid of quads; the shape moves the x = 0 column (same vertex count and order).
    let n = 5usize;
    let mut s = String::new();
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (x as f64 / 4.0, y as f64 / 4.0);
            s += &format!("v {u} {v} {}\nvt {u} {v}\n", 0.1 * (3.0 * u).sin());
        }
    }
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            let a = y * n + x + 1;
            let q = [a, a + 1, a + n + 1, a + n];
            s += &format!(
                "f {0}/{0} {1}/{1} {2}/{2} {3}/{3}\n",
                q[0], q[1], q[2], q[3]
            );
        }
    }
    let dir = std::env::temp_dir().join(format!("lgi-polys-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let neutral = dir.join("n.obj");
    std::fs::write(&neutral, &s).unwrap();
    let shape = dir.join("s.obj");
    std::fs::write(&shape, s.replace(" 0\nvt", " 0.05\nvt")).unwrap();
    let data = Dataset::from_obj_files(&neutral, &[shape]).unwrap();
    let polys = data.polygons().unwrap().clone();
    assert_eq!(polys.counts, vec![4; 16]);
    let markers = [
        (0.25, 0.25),
        (0.75, 0.25),
        (0.5, 0.5),
        (0.25, 0.75),
        (0.75, 0.75),
    ]
    .map(|(u, v): (f64, f64)| DVec3::new(u, v, 0.1 * (3.0 * u).sin()));
    let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
    let path = dir.join("m.lgi");
    lgi_core::save_model(&model, &path).unwrap();
    let back = lgi_core::load_model(&path).unwrap();
    assert_eq!(back.dataset().polygons(), Some(&polys));
    std::fs::remove_dir_all(&dir).ok();
}
