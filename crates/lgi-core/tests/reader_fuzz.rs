//! Fuzzing the readers (OBJ, glTF, the model file) with proptest: every input, however
//! malformed, gives `Ok` with a valid result or the reader's own error, never a panic (not
//! even one caught by a reader's guard), and a crafted model file with a valid checksum is a
//! `ModelFormat` error or a model that passes `Model::sanity_check` and solves to finite
//! vertices. `PROPTEST_CASES` sets the budget (scripts/fuzz.sh runs a long one, with
//! `LGI_FUZZ_TALLY` naming a file that receives one `target outcome` line per input); the
//! regression tests name the cases found by the reliability review (issue 14).

use lgi_core::{
    load_model, parse_obj, read_gltf, save_model, save_model_parts, BuildConfig, DVec2, DVec3,
    Dataset, LgiError, Mesh, Model, SolveOptions,
};
use proptest::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::OnceLock;

/// Appends `target outcome` to the file `$LGI_FUZZ_TALLY` names (the campaign's counts).
fn tally(target: &str, outcome: &str) {
    use std::io::Write;
    if let Some(path) = std::env::var_os("LGI_FUZZ_TALLY") {
        let mut f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .unwrap();
        // One write per line: appends of parallel tests do not interleave.
        f.write_all(format!("{target} {outcome}\n").as_bytes())
            .unwrap();
    }
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("lgi-fuzz-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A unique file path in `dir` (proptest cases run one after another, but paths stay unique).
fn fresh(dir: &Path, ext: &str) -> PathBuf {
    static N: AtomicUsize = AtomicUsize::new(0);
    dir.join(format!("case{}.{ext}", N.fetch_add(1, Ordering::Relaxed)))
}

// ---------------------------------------------------------------------------------------------
// glTF

fn base64(bytes: &[u8]) -> String {
    const T: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(T[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// The fields of a one-triangle glTF (positions, UVs, u16 indices, one morph target) that the
/// fuzzer varies; [`GltfCase::valid`] is a file that reads.
#[derive(Debug, Clone)]
struct GltfCase {
    position_accessor: usize,
    uv_accessor: Option<usize>,
    index_accessor: Option<usize>,
    target_accessor: Option<usize>,
    index_component: u32,
    index_type: &'static str,
    position_component: u32,
    position_type: &'static str,
    count: usize,
    stride: Option<usize>,
    offset: usize,
    view_length: usize,
    mode: u32,
}

impl GltfCase {
    fn valid() -> GltfCase {
        GltfCase {
            position_accessor: 0,
            uv_accessor: Some(2),
            index_accessor: Some(3),
            target_accessor: Some(1),
            index_component: 5123,
            index_type: "SCALAR",
            position_component: 5126,
            position_type: "VEC3",
            count: 3,
            stride: None,
            offset: 0,
            view_length: 36,
            mode: 4,
        }
    }

    fn json(&self) -> String {
        let pos: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let disp: [[f32; 3]; 3] = [[0.0, 0.0, 0.5], [0.0, 0.0, 0.0], [0.0, 0.0, -0.25]];
        let uv: [[f32; 2]; 3] = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let mut buf: Vec<u8> = Vec::new();
        for v in pos.iter().chain(&disp) {
            buf.extend(v.iter().flat_map(|x| x.to_le_bytes()));
        }
        for v in &uv {
            buf.extend(v.iter().flat_map(|x| x.to_le_bytes()));
        }
        buf.extend([0u16, 1, 2].iter().flat_map(|i| i.to_le_bytes()));
        buf.extend([0u8, 0]);
        let stride = self
            .stride
            .map_or(String::new(), |s| format!(r#","byteStride":{s}"#));
        let accessor = |view: usize, comp: u32, ty: &str, count: usize, offset: usize| {
            format!(
                r#"{{"bufferView":{view},"byteOffset":{offset},"componentType":{comp},"count":{count},"type":"{ty}","min":[0,0,0],"max":[1,1,1]}}"#
            )
        };
        let attr =
            |name: &str, a: Option<usize>| a.map_or(String::new(), |a| format!(r#","{name}":{a}"#));
        format!(
            r#"{{"asset":{{"version":"2.0"}},
"buffers":[{{"byteLength":{len},"uri":"data:application/octet-stream;base64,{b64}"}}],
"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{vl}{stride}}},{{"buffer":0,"byteOffset":36,"byteLength":36}},{{"buffer":0,"byteOffset":72,"byteLength":24}},{{"buffer":0,"byteOffset":96,"byteLength":6}}],
"accessors":[{a0},{a1},{a2},{a3}],
"meshes":[{{"primitives":[{{"mode":{mode},"attributes":{{"POSITION":{pa}{uv}}}{ix}{targets}}}]}}]}}"#,
            len = buf.len(),
            b64 = base64(&buf),
            vl = self.view_length,
            a0 = accessor(
                0,
                self.position_component,
                self.position_type,
                self.count,
                self.offset
            ),
            a1 = accessor(1, 5126, "VEC3", 3, 0),
            a2 = accessor(2, 5126, "VEC2", 3, 0),
            a3 = accessor(3, self.index_component, self.index_type, 3, 0),
            mode = self.mode,
            pa = self.position_accessor,
            uv = attr("TEXCOORD_0", self.uv_accessor),
            ix = self
                .index_accessor
                .map_or(String::new(), |a| format!(r#","indices":{a}"#)),
            targets = self.target_accessor.map_or(String::new(), |a| format!(
                r#","targets":[{{"POSITION":{a}}}]"#
            )),
        )
    }
}

fn gltf_case() -> impl Strategy<Value = GltfCase> {
    let acc = 0usize..7;
    let comp = prop::sample::select(vec![5120u32, 5121, 5122, 5123, 5125, 5126, 5130, 0]);
    let ty = prop::sample::select(vec!["SCALAR", "VEC2", "VEC3", "VEC4", "MAT4"]);
    (
        (
            acc.clone(),
            prop::option::of(acc.clone()),
            prop::option::of(acc.clone()),
            prop::option::of(acc),
        ),
        (comp.clone(), ty.clone(), comp, ty),
        (
            0usize..6,
            prop::option::of(0usize..40),
            0usize..40,
            0usize..120,
            0u32..8,
        ),
        prop::collection::vec(0usize..13, 0..4),
    )
        .prop_map(
            |((pa, ua, ia, ta), (ic, it, pc, pt), (count, stride, offset, vl, mode), fields)| {
                // A few fields fuzzed at a time, the others valid: most cases get past the
                // first check and reach the later ones.
                let mut case = GltfCase::valid();
                for f in fields {
                    match f {
                        0 => case.position_accessor = pa,
                        1 => case.uv_accessor = ua,
                        2 => case.index_accessor = ia,
                        3 => case.target_accessor = ta,
                        4 => case.index_component = ic,
                        5 => case.index_type = it,
                        6 => case.position_component = pc,
                        7 => case.position_type = pt,
                        8 => case.count = count,
                        9 => case.stride = stride,
                        10 => case.offset = offset,
                        11 => case.view_length = vl,
                        _ => case.mode = mode,
                    }
                }
                case
            },
        )
}

/// Reads a glTF and checks the reader's promise: `Ok` is a valid dataset, `Err` names the
/// file, and no panic happened (not even one the reader's guard caught).
fn check_gltf(target: &str, dir: &Path, text: &str) -> Result<(), TestCaseError> {
    let p = fresh(dir, "gltf");
    std::fs::write(&p, text).unwrap();
    let name = p.file_name().unwrap().to_string_lossy().to_string();
    match read_gltf(&p) {
        Ok(d) => {
            prop_assert!(d.neutral().positions.iter().all(|x| x.is_finite()));
            tally(target, "accepted");
        }
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(msg.contains(&name), "error does not name the file: {msg}");
            prop_assert!(
                !msg.contains("the glTF parser failed"),
                "a panic reached the guard (an accessor check is missing): {msg}"
            );
            tally(target, "refused");
        }
    }
    let _ = std::fs::remove_file(&p);
    Ok(())
}

#[test]
fn the_valid_fuzz_template_reads() {
    let dir = scratch("gltf-template");
    let p = fresh(&dir, "gltf");
    std::fs::write(&p, GltfCase::valid().json()).unwrap();
    let d = read_gltf(&p).unwrap();
    assert_eq!(d.num_vertices(), 3);
    assert_eq!(d.num_shapes(), 1);
    assert_eq!(d.displacement(0, 2), DVec3::new(0.0, 0.0, -0.25));
}

#[test]
fn gltf_attribute_accessor_out_of_range_is_an_error_naming_the_file_not_a_panic() {
    let dir = scratch("gltf-oor");
    let case = GltfCase {
        position_accessor: 99,
        ..GltfCase::valid()
    };
    let p = fresh(&dir, "gltf");
    std::fs::write(&p, case.json()).unwrap();
    let e = read_gltf(&p).unwrap_err();
    assert!(
        matches!(e, LgiError::Io { .. } | LgiError::Parse { .. }),
        "{e:?}"
    );
    assert!(
        e.to_string()
            .contains(p.file_name().unwrap().to_str().unwrap()),
        "{e}"
    );
}

#[test]
fn gltf_float_index_accessor_is_a_parse_error_naming_indices() {
    let dir = scratch("gltf-float-indices");
    let case = GltfCase {
        index_component: 5126,
        index_accessor: Some(3),
        ..GltfCase::valid()
    };
    let p = fresh(&dir, "gltf");
    std::fs::write(&p, case.json()).unwrap();
    let e = read_gltf(&p).unwrap_err();
    assert!(matches!(e, LgiError::Parse { .. }), "{e:?}");
    assert!(e.to_string().contains("indices"), "{e}");
}

#[test]
fn gltf_byte_stride_smaller_than_the_element_is_a_parse_error() {
    let dir = scratch("gltf-stride");
    let case = GltfCase {
        stride: Some(4),
        ..GltfCase::valid()
    };
    let p = fresh(&dir, "gltf");
    std::fs::write(&p, case.json()).unwrap();
    let e = read_gltf(&p).unwrap_err();
    assert!(matches!(e, LgiError::Parse { .. }), "{e:?}");
    assert!(e.to_string().contains("byteStride 4"), "{e}");
}

proptest! {
    #[test]
    fn gltf_with_fuzzed_accessors_never_panics(case in gltf_case()) {
        static DIR: OnceLock<PathBuf> = OnceLock::new();
        let dir = DIR.get_or_init(|| scratch("gltf-fuzz"));
        check_gltf("gltf-accessors", dir, &case.json())?;
    }

    #[test]
    fn gltf_with_random_bytes_replaced_never_panics(
        edits in prop::collection::vec((0usize..4000, any::<u8>()), 1..6)
    ) {
        static DIR: OnceLock<PathBuf> = OnceLock::new();
        let dir = DIR.get_or_init(|| scratch("gltf-bytes"));
        let mut bytes = GltfCase::valid().json().into_bytes();
        for (at, b) in edits {
            let i = at % bytes.len();
            // Digits and structural characters: edits that keep the JSON mostly parseable.
            bytes[i] = b"0123456789,:{}[]\"-e."[b as usize % 20];
        }
        check_gltf("gltf-bytes", dir, &String::from_utf8_lossy(&bytes))?;
    }
}

// ---------------------------------------------------------------------------------------------
// OBJ

fn obj_line() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        (-3.0f64..3.0).prop_map(|x| x.to_string()),
        Just("nan".to_string()),
        Just("inf".to_string()),
        Just("1e308".to_string()),
        Just("1e400".to_string()),
        Just("-0".to_string()),
        Just("x".to_string()),
    ];
    let idx = prop_oneof![
        (-6i64..8).prop_map(|i| i.to_string()),
        (-6i64..8, -6i64..8).prop_map(|(a, b)| format!("{a}/{b}")),
        (-6i64..8).prop_map(|a| format!("{a}//{a}")),
        Just("18446744073709551617".to_string()),
        Just("/".to_string()),
    ];
    prop_oneof![
        prop::collection::vec(num.clone(), 0..5).prop_map(|v| format!("v {}", v.join(" "))),
        prop::collection::vec(num, 0..4).prop_map(|v| format!("vt {}", v.join(" "))),
        prop::collection::vec(idx, 0..6).prop_map(|v| format!("f {}", v.join(" "))),
        Just("# comment".to_string()),
        Just("f 1/1 2/2 3/3".to_string()),
        Just("f 3/3 2/2 1/1".to_string()),
        Just("v 0.5 0.5 0.25".to_string()),
        Just("o thing".to_string()),
        Just(String::new()),
    ]
}

proptest! {
    #[test]
    fn obj_of_random_lines_never_panics_and_ok_is_a_valid_mesh(
        lines in prop::collection::vec(obj_line(), 0..24)
    ) {
        let text = format!(
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n{}\n",
            lines.join("\n")
        );
        match parse_obj(&text, Path::new("fuzz.obj")) {
            Ok(mesh) => {
                prop_assert!(mesh.validate("fuzz.obj").is_ok());
                prop_assert!(mesh.positions.iter().all(|p| p.is_finite()));
                tally("obj-lines", "accepted");
            }
            Err(e) => {
                prop_assert!(e.to_string().contains("fuzz.obj"), "{e}");
                tally("obj-lines", "refused");
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Model files

/// A wavy 14×14 patch with UVs and four smooth shapes, and 12 markers on it.
fn patch() -> (Dataset, Vec<DVec3>) {
    let n = 14;
    let z = |u: f64, v: f64| 0.1 * (3.0 * u).sin() * (2.0 * v).cos();
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    for y in 0..n {
        for x in 0..n {
            let (u, v) = (x as f64 / (n - 1) as f64, y as f64 / (n - 1) as f64);
            positions.push(DVec3::new(u, v, z(u, v)));
            uvs.push(DVec2::new(u, v));
        }
    }
    let mut triangles = Vec::new();
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            let a = (y * n + x) as u32;
            let (b, c, d) = (a + 1, a + n as u32 + 1, a + n as u32);
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    let mesh = Mesh {
        positions: positions.clone(),
        uv_triangles: triangles.clone(),
        triangles,
        uvs,
    };
    let shapes = (0..4)
        .map(|k| {
            let f = k as f64 + 1.0;
            let pos = positions
                .iter()
                .map(|p| *p + DVec3::new(0.0, 0.0, 0.05 * (f * p.x + 0.3 * f * p.y).sin()))
                .collect();
            (format!("s{k}"), pos)
        })
        .collect();
    let data = Dataset::from_shape_positions(mesh, shapes).unwrap();
    let mut markers = Vec::new();
    for &v in &[0.2, 0.5, 0.8] {
        for &u in &[0.15, 0.4, 0.6, 0.85] {
            markers.push(DVec3::new(u, v, z(u, v)));
        }
    }
    (data, markers)
}

fn patch_model() -> &'static (Model, Vec<u8>) {
    static M: OnceLock<(Model, Vec<u8>)> = OnceLock::new();
    M.get_or_init(|| {
        let (data, markers) = patch();
        let model = Model::build(&data, &markers, &BuildConfig::default()).unwrap();
        let dir = scratch("model-base");
        let p = dir.join("base.lgi");
        save_model(&model, &p).unwrap();
        (model, std::fs::read(&p).unwrap())
    })
}

/// Header: magic (8), version (4), payload length (8), checksum (8).
const HEADER: usize = 28;

/// Re-sums a model file after its payload was edited (what an attacker or a foreign writer
/// would do): only the loader's own checks can refuse it then.
fn resum(bytes: &mut [u8]) {
    let sum = checksum(&bytes[HEADER..]);
    bytes[20..28].copy_from_slice(&sum.to_le_bytes());
}

/// The version 3 checksum (docs/file-formats.md): FNV-1a over 8-byte words in four lanes,
/// folded with the length, then byte-wise FNV-1a over the tail. Re-implemented here from the
/// format's description, so the test also pins the format.
fn checksum(bytes: &[u8]) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut lanes = [
        OFFSET,
        0x8422_2325_cbf2_9ce4,
        0x9ce4_8422_2325_cbf2,
        0x2325_cbf2_9ce4_8422,
    ];
    let mut blocks = bytes.chunks_exact(32);
    for block in &mut blocks {
        for (lane, word) in lanes.iter_mut().zip(block.chunks_exact(8)) {
            *lane = (*lane ^ u64::from_le_bytes(word.try_into().unwrap())).wrapping_mul(PRIME);
        }
    }
    let mut h = (bytes.len() as u64).wrapping_mul(PRIME);
    for lane in lanes {
        h = (h ^ lane).wrapping_mul(PRIME);
        h ^= h >> 29;
    }
    blocks
        .remainder()
        .iter()
        .fold(h, |h, &b| (h ^ b as u64).wrapping_mul(PRIME))
}

/// Loads `bytes` and checks the loader's promise: a `ModelFormat` error, or a model that
/// passes its sanity check and solves its rest markers to finite vertices.
fn check_model_bytes(target: &str, dir: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let p = fresh(dir, "lgi");
    std::fs::write(&p, bytes).unwrap();
    match load_model(&p) {
        Ok(m) => {
            prop_assert!(m.sanity_check().is_ok(), "{:?}", m.sanity_check());
            let frames = [m.markers_rest().to_vec()];
            let mut vertices = vec![DVec3::ZERO; m.dataset().num_vertices()];
            match m.solve(
                &frames,
                &SolveOptions::default(),
                None,
                &mut vertices,
                |_| {},
            ) {
                Ok(_) => prop_assert!(vertices.iter().all(|v| v.is_finite())),
                Err(e) => prop_assert!(matches!(e, LgiError::Input(_)), "{e:?}"),
            }
            tally(target, "loaded");
        }
        Err(e) => {
            prop_assert!(matches!(e, LgiError::ModelFormat { .. }), "{e:?}");
            prop_assert!(
                !e.to_string().contains("loading it failed"),
                "a panic reached the loader's guard: {e}"
            );
            tally(target, "refused");
        }
    }
    let _ = std::fs::remove_file(&p);
    Ok(())
}

#[test]
fn the_checksum_reimplementation_matches_the_writer() {
    let (_, bytes) = patch_model();
    let mut copy = bytes.clone();
    resum(&mut copy);
    assert_eq!(&copy, bytes);
}

#[test]
fn a_built_model_passes_its_sanity_check_and_so_does_its_reload() {
    let (model, bytes) = patch_model();
    model.sanity_check().unwrap();
    let dir = scratch("model-reload");
    let p = dir.join("m.lgi");
    std::fs::write(&p, bytes).unwrap();
    load_model(&p).unwrap().sanity_check().unwrap();
}

/// Edits the parts of the patch model, saves them (valid checksum), loads: must be a
/// `ModelFormat` error whose message contains `expect`.
fn crafted_is_refused(edit: impl FnOnce(&mut lgi_core::ModelParts), expect: &str) {
    let (model, _) = patch_model();
    let mut parts = model.to_parts();
    edit(&mut parts);
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    let p = fresh(DIR.get_or_init(|| scratch("crafted")), "lgi");
    save_model_parts(&parts.as_parts_ref(), &p).unwrap();
    match load_model(&p) {
        Err(e @ LgiError::ModelFormat { .. }) => {
            assert!(e.to_string().contains(expect), "{e}")
        }
        other => panic!("expected ModelFormat containing {expect:?}, got {other:?}"),
    }
}

#[test]
fn crafted_model_with_zero_markers_is_a_format_error_not_a_panic() {
    crafted_is_refused(
        |p| {
            p.markers_rest.clear();
            for b in &mut p.bins {
                b.clouds.clear();
                b.tets.clear();
            }
        },
        "0 markers",
    );
}

#[test]
fn crafted_model_with_an_empty_cloud_is_a_format_error_not_a_solve_panic() {
    crafted_is_refused(
        |p| {
            p.bins[0].clouds[2].points.clear();
            p.bins[0].clouds[2].aliases.clear();
            p.bins[0].tets[2].clear();
        },
        "bundle 2: empty cloud",
    );
}

#[test]
fn crafted_model_whose_markers_are_off_the_surface_is_a_format_error_not_a_marker_error() {
    crafted_is_refused(|p| p.markers_rest[1].z += 5.0, "marker 1");
}

#[test]
fn crafted_model_with_a_bad_config_is_a_format_error_not_an_input_error() {
    crafted_is_refused(|p| p.config.max_edge = -1.0, "max_edge");
}

#[test]
fn crafted_model_with_duplicate_aliases_or_bad_tets_is_a_format_error() {
    crafted_is_refused(
        |p| {
            let c = &mut p.bins[0].clouds[0];
            let first = c.aliases[0][0];
            c.aliases.last_mut().unwrap().push(first);
        },
        "bundle 0",
    );
    crafted_is_refused(
        |p| {
            if let Some(t) = p.bins[0].tets[3].first_mut() {
                t[1] = t[0];
            } else {
                p.bins[0].tets[3].push([0, 0, 0, 0]);
            }
        },
        "bundle 3: tet",
    );
}

#[test]
fn crafted_model_with_a_far_away_marker_is_a_format_error() {
    crafted_is_refused(|p| p.markers_rest[0] = DVec3::splat(1e30), "marker 0");
}

/// An interesting 8-byte value for a word of the payload (counts, floats, indices).
fn word() -> impl Strategy<Value = [u8; 8]> {
    prop_oneof![
        (0u64..64).prop_map(u64::to_le_bytes),
        Just(u64::MAX.to_le_bytes()),
        Just((u32::MAX as u64).to_le_bytes()),
        prop::sample::select(vec![
            0.0f64,
            -1.0,
            1e30,
            1e300,
            f64::NAN,
            f64::INFINITY,
            0.5,
            1e-300
        ])
        .prop_map(f64::to_le_bytes),
        any::<u64>().prop_map(u64::to_le_bytes),
    ]
}

proptest! {
    #[test]
    fn model_file_with_words_overwritten_and_checksum_recomputed_loads_valid_or_is_a_format_error(
        edits in prop::collection::vec((0.0f64..1.0, word(), any::<bool>()), 1..4)
    ) {
        static DIR: OnceLock<PathBuf> = OnceLock::new();
        let dir = DIR.get_or_init(|| scratch("model-fuzz"));
        let (_, base) = patch_model();
        let mut bytes = base.clone();
        let payload = bytes.len() - HEADER;
        for (at, w, aligned) in edits {
            let mut i = (at * (payload - 8) as f64) as usize;
            if aligned {
                i -= i % 8; // the payload is mostly 8-byte words
            }
            bytes[HEADER + i..HEADER + i + 8].copy_from_slice(&w);
        }
        resum(&mut bytes);
        check_model_bytes("model-words", dir, &bytes)?;
    }

    #[test]
    fn model_file_truncated_or_extended_with_a_fixed_header_is_a_format_error(
        cut in 0usize..5000, extra in prop::collection::vec(any::<u8>(), 0..16)
    ) {
        static DIR: OnceLock<PathBuf> = OnceLock::new();
        let dir = DIR.get_or_init(|| scratch("model-cut"));
        let (_, base) = patch_model();
        let keep = base.len() - HEADER - (cut % (base.len() - HEADER));
        let mut bytes = base[..HEADER + keep].to_vec();
        bytes.extend(&extra);
        let len = (bytes.len() - HEADER) as u64;
        bytes[12..20].copy_from_slice(&len.to_le_bytes());
        resum(&mut bytes);
        if bytes != *base {
            check_model_bytes("model-cut", dir, &bytes)?;
        }
    }
}
