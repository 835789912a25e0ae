//! Readers against malformed and edge-case files: every error must carry the right variant and
//! name the file, line or element; plus glTF round trips and the real ICT data when present.

mod common;

use lgi_core::{
    parse_obj, read_gltf, read_obj, read_obj_positions, write_obj, DVec2, DVec3, Dataset, LgiError,
    Mesh,
};
use proptest::prelude::*;
use std::path::{Path, PathBuf};

/// A fresh scratch directory per test (no tempfile crate in the workspace).
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lgi-io-tests-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// Parses `text` as "bad.obj" and returns the Parse error's line and message.
fn parse_err(text: &str) -> (usize, String) {
    match parse_obj(text, Path::new("bad.obj")) {
        Err(e @ LgiError::Parse { .. }) => {
            let msg = e.to_string();
            assert!(
                msg.starts_with("bad.obj:"),
                "message must name the file: {msg}"
            );
            let LgiError::Parse { line, .. } = e else {
                unreachable!()
            };
            (line, msg)
        }
        other => panic!("expected a Parse error, got {other:?}"),
    }
}

const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

#[test]
fn truncated_vertex_line_names_file_and_line() {
    let (line, msg) = parse_err("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n");
    assert_eq!(line, 2);
    assert!(
        msg.contains("bad.obj:2:") && msg.contains("truncated"),
        "{msg}"
    );
}

#[test]
fn truncated_texture_coordinate_line_is_rejected() {
    let (line, msg) = parse_err(&format!("{TRI}vt 0.5\nf 1/1 2/1 3/1\n"));
    assert_eq!(line, 4);
    assert!(msg.contains("truncated texture-coordinate"), "{msg}");
}

#[test]
fn garbled_number_names_the_token_and_line() {
    let (line, msg) = parse_err("v 0 0 0\nv 1 0 0\nv 0 1.2.3 0\nf 1 2 3\n");
    assert_eq!(line, 3);
    assert!(msg.contains("'1.2.3'") && msg.contains("vertex"), "{msg}");
}

#[test]
fn binary_garbage_is_a_parse_error_not_a_panic() {
    let bytes: Vec<u8> = (0..2000u32).map(|i| (i * 37 % 251) as u8).collect();
    let dir = scratch("garbage");
    let p = dir.join("garbage.obj");
    std::fs::write(&p, &bytes).unwrap();
    let e = read_obj(&p).unwrap_err();
    assert!(
        matches!(e, LgiError::Parse { .. } | LgiError::Dataset(_)),
        "{e:?}"
    );
    assert!(e.to_string().contains("garbage.obj"), "{e}");
}

#[test]
fn nan_and_infinite_coordinates_are_rejected_naming_the_line() {
    for bad in ["nan", "NaN", "inf", "-inf"] {
        let (line, msg) = parse_err(&format!("v 0 0 0\nv 1 {bad} 0\nv 0 1 0\nf 1 2 3\n"));
        assert_eq!(line, 2, "{msg}");
        assert!(msg.contains("non-finite") && msg.contains(bad), "{msg}");
    }
}

#[test]
fn index_zero_is_rejected_naming_the_line() {
    let (line, msg) = parse_err(&format!("{TRI}f 0 1 2\n"));
    assert_eq!(line, 4);
    assert!(msg.contains("index 0"), "{msg}");
}

#[test]
fn index_out_of_range_names_the_index_and_line() {
    let (line, msg) = parse_err(&format!("{TRI}f 1 2 3\nf 1 2 7\n"));
    assert_eq!(line, 5);
    assert!(
        msg.contains("vertex index 7") && msg.contains("has 3 vertices"),
        "{msg}"
    );
}

#[test]
fn uv_index_out_of_range_is_rejected() {
    let (line, msg) = parse_err(&format!("{TRI}vt 0 0\nf 1/1 2/1 3/2\n"));
    assert_eq!(line, 5);
    assert!(msg.contains("texture coordinate index 2"), "{msg}");
}

#[test]
fn relative_index_before_the_first_vertex_is_rejected() {
    let (line, msg) = parse_err(&format!("{TRI}f -1 -2 -4\n"));
    assert_eq!(line, 4);
    assert!(msg.contains("-4"), "{msg}");
}

#[test]
fn garbled_index_is_rejected() {
    let (line, msg) = parse_err(&format!("{TRI}f 1 2x 3\n"));
    assert_eq!(line, 4);
    assert!(msg.contains("'2x'"), "{msg}");
}

#[test]
fn face_with_fewer_than_three_corners_is_rejected() {
    let (line, msg) = parse_err(&format!("{TRI}f 1 2\n"));
    assert_eq!(line, 4);
    assert!(msg.contains("2 corners"), "{msg}");
}

#[test]
fn faces_mixing_uv_and_no_uv_are_rejected_naming_both_lines() {
    let (line, msg) = parse_err(&format!("{TRI}v 1 1 0\nvt 0 0\nf 1/1 2/1 3/1\nf 2 4 3\n"));
    assert_eq!(line, 7);
    assert!(msg.contains("line 6"), "{msg}");
    let (line, msg) = parse_err(&format!("{TRI}vt 0 0\nf 1/1 2 3/1\n"));
    assert_eq!(line, 5);
    assert!(msg.contains("mixes"), "{msg}");
}

#[test]
fn face_repeating_a_vertex_is_rejected() {
    let (line, msg) = parse_err(&format!("{TRI}f 1 2 1\n"));
    assert_eq!(line, 4);
    assert!(msg.contains("repeats vertex 1"), "{msg}");
}

#[test]
fn file_without_faces_is_a_dataset_error_naming_the_file() {
    let e = parse_obj(TRI, Path::new("nofaces.obj")).unwrap_err();
    assert!(matches!(e, LgiError::Dataset(_)), "{e:?}");
    assert!(e.to_string().contains("nofaces.obj"), "{e}");
}

#[test]
fn missing_file_is_an_io_error_naming_the_path() {
    let p = Path::new("/nonexistent/lgi/neutral.obj");
    for e in [
        read_obj(p).unwrap_err(),
        read_obj_positions(p, 3).unwrap_err(),
        Dataset::from_obj_files(p, &[]).unwrap_err(),
        read_gltf(Path::new("/nonexistent/lgi/face.gltf")).unwrap_err(),
    ] {
        assert!(matches!(e, LgiError::Io { .. }), "{e:?}");
        assert!(e.to_string().contains("/nonexistent/lgi/"), "{e}");
    }
}

#[test]
fn missing_shape_file_is_an_io_error_naming_that_file() {
    let dir = scratch("missing-shape");
    let neutral = write(&dir, "neutral.obj", &format!("{TRI}f 1 2 3\n"));
    let e = Dataset::from_obj_files(&neutral, &[dir.join("gone.obj")]).unwrap_err();
    assert!(matches!(e, LgiError::Io { .. }), "{e:?}");
    assert!(e.to_string().contains("gone.obj"), "{e}");
}

#[test]
fn shape_with_other_vertex_count_is_rejected_naming_the_file() {
    let dir = scratch("mismatch");
    let neutral = write(&dir, "neutral.obj", &format!("{TRI}f 1 2 3\n"));
    let good = write(&dir, "smile.obj", "v 0 0 1\nv 1 0 1\nv 0 1 1\nf 1 2 3\n");
    let bad = write(&dir, "frown.obj", "v 0 0 1\nv 1 0 1\nv 0 1 1\nv 5 5 5\n");
    let e = Dataset::from_obj_files(&neutral, &[good.clone(), bad]).unwrap_err();
    assert!(matches!(e, LgiError::Dataset(_)), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("frown.obj") && msg.contains("4 vertices") && msg.contains("3"),
        "{msg}"
    );

    let d = Dataset::from_obj_files(&neutral, &[good]).unwrap();
    assert_eq!(d.names(), ["smile"]);
    assert_eq!(d.displacement(0, 1), DVec3::Z);
}

#[test]
fn garbled_shape_file_names_the_file_and_line() {
    let dir = scratch("garbled-shape");
    let neutral = write(&dir, "neutral.obj", &format!("{TRI}f 1 2 3\n"));
    let bad = write(&dir, "jawOpen.obj", "v 0 0 1\nv 1 0 1\nv 0 x 1\n");
    let e = Dataset::from_obj_files(&neutral, &[bad]).unwrap_err();
    assert!(matches!(e, LgiError::Parse { line: 3, .. }), "{e:?}");
    assert!(e.to_string().contains("jawOpen.obj:3:"), "{e}");
}

#[test]
fn negative_indices_equal_their_positive_counterparts() {
    let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";
    let pos = parse_obj(&format!("{text}f 1/1 2/2 3/3 4/4\n"), Path::new("a.obj")).unwrap();
    let neg = parse_obj(
        &format!("{text}f -4/-4 -3/-3 -2/-2 -1/-1\n"),
        Path::new("b.obj"),
    )
    .unwrap();
    assert_eq!(pos, neg);
    // Relative indices count only the elements defined before the face.
    let m = parse_obj(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -4 -3 -1\n",
        Path::new("c.obj"),
    )
    .unwrap();
    assert_eq!(m.triangles, vec![[0, 1, 2], [0, 1, 3]]);
}

#[test]
fn all_corner_forms_are_accepted() {
    let text = format!("{TRI}vt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1\n");
    let m = parse_obj(&text, Path::new("a.obj")).unwrap();
    assert_eq!(m.uv_triangles, vec![[0, 1, 2]]);
    let m = parse_obj(
        &format!("{TRI}vn 0 0 1\nf 1//1 2//1 3//1\n"),
        Path::new("b.obj"),
    )
    .unwrap();
    assert!(!m.has_uvs());
}

#[test]
fn uv_seam_is_kept_vertex_with_two_uvs() {
    // Two quads share the edge 2-5; vertex 2 (index 1) is on a UV seam: UV 2 in the first
    // quad, UV 5 in the second.
    let text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\n\
                vt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nvt 0.6 0\nvt 1 0\nvt 1 1\nvt 0.6 1\n\
                f 1/1 2/2 5/3 4/4\nf 2/5 3/6 6/7 5/8\n";
    let m = parse_obj(text, Path::new("seam.obj")).unwrap();
    assert_eq!(m.num_vertices(), 6);
    assert_eq!(m.uvs.len(), 8);
    assert_eq!(m.triangles.len(), 4);
    let uvs_of_vertex_1: std::collections::BTreeSet<u32> = m
        .triangles
        .iter()
        .zip(&m.uv_triangles)
        .flat_map(|(t, u)| (0..3).filter(|&c| t[c] == 1).map(move |c| u[c]))
        .collect();
    assert_eq!(uvs_of_vertex_1, [1, 4].into_iter().collect());
    assert_eq!(m.uvs[4], DVec2::new(0.6, 0.0));
}

/// Area of a triangle, for the fan-split check.
fn area(m: &Mesh, t: usize) -> f64 {
    let [a, b, c] = m.triangle(t);
    (b - a).cross(c - a).length() / 2.0
}

proptest! {
    #![proptest_config(ProptestConfig {
        cases: 64,
        rng_seed: proptest::test_runner::RngSeed::Fixed(7),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// A convex n-gon becomes n-2 triangles covering exactly its area (closed form
    /// n/2 sin(2π/n) for the unit regular polygon), each using the first corner (fan).
    #[test]
    fn ngon_is_fan_split_into_n_minus_2_triangles(n in 3usize..40) {
        let mut text = String::new();
        for k in 0..n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            text.push_str(&format!("v {} {} 0\n", a.cos(), a.sin()));
        }
        text.push('f');
        for k in 1..=n {
            text.push_str(&format!(" {k}"));
        }
        let m = parse_obj(&text, Path::new("ngon.obj")).unwrap();
        prop_assert_eq!(m.triangles.len(), n - 2);
        prop_assert!(m.triangles.iter().all(|t| t[0] == 0));
        let total: f64 = (0..m.triangles.len()).map(|t| area(&m, t)).sum();
        let exact = n as f64 / 2.0 * (std::f64::consts::TAU / n as f64).sin();
        prop_assert!((total - exact).abs() < 1e-12, "{} vs {}", total, exact);
    }

    /// Writing then reading gives back the same positions, triangles and UVs, bit for bit.
    #[test]
    fn written_obj_reads_back_exactly(
        coords in proptest::collection::vec(-1e3f64..1e3, 12),
        uv in proptest::collection::vec(0f64..1.0, 8),
    ) {
        let mesh = Mesh {
            positions: coords.chunks(3).map(|c| DVec3::new(c[0], c[1], c[2])).collect(),
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            uvs: uv.chunks(2).map(|c| DVec2::new(c[0], c[1])).collect(),
            uv_triangles: vec![[0, 1, 2], [3, 1, 2]],
        };
        let dir = scratch("roundtrip");
        let p = dir.join("out.obj");
        write_obj(&p, &mesh.positions, &mesh).unwrap();
        prop_assert_eq!(read_obj(&p).unwrap(), mesh);
    }
}

#[test]
fn write_obj_rejects_wrong_position_count() {
    let mesh = parse_obj(&format!("{TRI}f 1 2 3\n"), Path::new("a.obj")).unwrap();
    let e = write_obj(Path::new("/tmp/never.obj"), &[DVec3::ZERO], &mesh).unwrap_err();
    assert!(matches!(e, LgiError::Input(_)), "{e:?}");
}

// ---------------------------------------------------------------------------------- glTF

fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let b = [c[0], *c.get(1).unwrap_or(&0), *c.get(2).unwrap_or(&0)];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

const POS: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
const UV: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
const T0: [[f32; 3]; 3] = [[0.0, 0.0, 0.5], [0.0, 0.0, 0.0], [0.0, 0.0, -0.25]];
const T1: [[f32; 3]; 3] = [[0.125, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.0]];

/// A one-triangle glTF with UVs, u16 indices and two morph targets, buffer as a data URI.
fn triangle_gltf(extras: &str) -> String {
    let mut buf: Vec<u8> = Vec::new();
    for v in POS.iter().chain(&T0).chain(&T1) {
        buf.extend(v.iter().flat_map(|x| x.to_le_bytes()));
    }
    for v in &UV {
        buf.extend(v.iter().flat_map(|x| x.to_le_bytes()));
    }
    // Indices in reverse winding order, to prove they are read rather than assumed.
    buf.extend([0u16, 2, 1].iter().flat_map(|i| i.to_le_bytes()));
    buf.extend([0u8, 0]);
    let len = buf.len();
    let view =
        |off: usize, n: usize| format!(r#"{{"buffer":0,"byteOffset":{off},"byteLength":{n}}}"#);
    let vec3 = |view: usize, min: [f32; 3], max: [f32; 3]| {
        format!(
            r#"{{"bufferView":{view},"componentType":5126,"count":3,"type":"VEC3","min":{min:?},"max":{max:?}}}"#
        )
    };
    format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "buffers": [{{"byteLength": {len}, "uri": "data:application/octet-stream;base64,{b64}"}}],
  "bufferViews": [{v0}, {v1}, {v2}, {v3}, {v4}],
  "accessors": [
    {a0}, {a1}, {a2},
    {{"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC2"}},
    {{"bufferView": 4, "componentType": 5123, "count": 3, "type": "SCALAR"}}
  ],
  "meshes": [{{
    "name": "face",
    {extras}
    "primitives": [{{
      "attributes": {{"POSITION": 0, "TEXCOORD_0": 3}},
      "indices": 4,
      "targets": [{{"POSITION": 1}}, {{"POSITION": 2}}]
    }}]
  }}]
}}"#,
        b64 = base64(&buf),
        v0 = view(0, 36),
        v1 = view(36, 36),
        v2 = view(72, 36),
        v3 = view(108, 24),
        v4 = view(132, 6),
        a0 = vec3(0, [0.0, 0.0, 0.0], [1.0, 1.0, 0.0]),
        a1 = vec3(1, [0.0, 0.0, -0.25], [0.0, 0.0, 0.5]),
        a2 = vec3(2, [0.0, 0.0, 0.0], [0.125, 2.0, 0.0]),
    )
}

#[test]
fn base64_helper_matches_known_vectors() {
    assert_eq!(base64(b"foobar"), "Zm9vYmFy");
    assert_eq!(base64(b"fooba"), "Zm9vYmE=");
    assert_eq!(base64(b"foob"), "Zm9vYg==");
}

#[test]
fn gltf_morph_targets_become_named_shapes_with_exact_values() {
    let dir = scratch("gltf-named");
    let p = write(
        &dir,
        "tri.gltf",
        &triangle_gltf(r#""extras": {"targetNames": ["jawOpen", "smile"]},"#),
    );
    let d = read_gltf(&p).unwrap();
    assert_eq!(d.num_vertices(), 3);
    assert_eq!(d.names(), ["jawOpen", "smile"]);
    let m = d.neutral();
    assert_eq!(m.triangles, vec![[0, 2, 1]]);
    assert_eq!(m.uv_triangles, m.triangles);
    for v in 0..3 {
        assert_eq!(m.positions[v], DVec3::from(POS[v].map(f64::from)));
        // glTF's v runs down the image; the dataset's runs up (OBJ's convention).
        let [u, t] = UV[v].map(f64::from);
        assert_eq!(m.uvs[v], DVec2::new(u, 1.0 - t));
        assert_eq!(d.displacement(0, v), DVec3::from(T0[v].map(f64::from)));
        assert_eq!(d.displacement(1, v), DVec3::from(T1[v].map(f64::from)));
    }
}

#[test]
fn gltf_targets_without_names_are_numbered() {
    let dir = scratch("gltf-unnamed");
    let p = write(&dir, "tri.gltf", &triangle_gltf(""));
    assert_eq!(read_gltf(&p).unwrap().names(), ["target0", "target1"]);
}

#[test]
fn gltf_with_wrong_number_of_target_names_is_rejected_naming_the_file() {
    let dir = scratch("gltf-badnames");
    let p = write(
        &dir,
        "tri.gltf",
        &triangle_gltf(r#""extras": {"targetNames": ["one"]},"#),
    );
    let e = read_gltf(&p).unwrap_err();
    assert!(matches!(e, LgiError::Parse { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("tri.gltf") && msg.contains("1 names for 2"),
        "{msg}"
    );
}

#[test]
fn garbled_gltf_is_a_parse_error_naming_the_file() {
    let dir = scratch("gltf-garbled");
    let p = write(
        &dir,
        "broken.gltf",
        r#"{"asset": {"version": "2.0"}, "meshes": [{"#,
    );
    let e = read_gltf(&p).unwrap_err();
    assert!(matches!(e, LgiError::Parse { .. }), "{e:?}");
    assert!(e.to_string().contains("broken.gltf"), "{e}");
    let p = write(&dir, "empty.gltf", r#"{"asset": {"version": "2.0"}}"#);
    let e = read_gltf(&p).unwrap_err();
    assert!(
        e.to_string().contains("empty.gltf") && e.to_string().contains("no mesh"),
        "{e}"
    );
}

// ---------------------------------------------------------------------------------- ICT

use common::ict_dir;

#[test]
fn ict_neutral_and_57_shapes_load_with_expected_counts() {
    let Some(dir) = ict_dir() else {
        println!(
            "skipped: ICT FaceKit data not found (set LGI_SHARED_DATA or put it in ../shared/data)"
        );
        return;
    };
    let mut shapes: Vec<PathBuf> = std::fs::read_dir(dir.join("shapes"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "obj"))
        .collect();
    shapes.sort();
    let t0 = std::time::Instant::now();
    let neutral = read_obj(&dir.join("generic_neutral_mesh.obj")).unwrap();
    let t_neutral = t0.elapsed();
    let t1 = std::time::Instant::now();
    let d = Dataset::from_obj_files(&dir.join("generic_neutral_mesh.obj"), &shapes).unwrap();
    let t_all = t1.elapsed();
    println!(
        "ICT neutral parse: {t_neutral:?}; neutral + {} shapes: {t_all:?}",
        shapes.len()
    );
    assert_eq!(d.num_vertices(), 26719);
    assert_eq!(d.num_shapes(), 57);
    assert_eq!(d.neutral().triangles.len(), 548 + 2 * 25836);
    assert_eq!(d.neutral(), &neutral);
    assert!(d.neutral().has_uvs());
    assert_eq!(d.neutral().uvs.len(), 28911);
    assert!(d.names().iter().any(|n| n == "jawOpen"), "{:?}", d.names());
}
