//! Tests of the model file: checksums, what survives save and load (names, unit, polygons,
//! datasets), older versions, and corrupt bytes as format errors.

use super::*;

fn bytes(n: usize) -> Vec<u8> {
    let mut x = 0x2545_f491_4f6c_dd1du64;
    (0..n)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect()
}

#[test]
fn checksum_changes_with_every_single_bit_flip_and_with_truncation() {
    for n in [0usize, 1, 7, 31, 32, 33, 100, 1000] {
        let b = bytes(n);
        let h = checksum(&b);
        for i in 0..n {
            for bit in [0u8, 3, 7] {
                let mut c = b.clone();
                c[i] ^= 1 << bit;
                assert_ne!(checksum(&c), h, "n {n} byte {i} bit {bit}");
            }
        }
        if n > 0 {
            assert_ne!(checksum(&b[..n - 1]), h, "truncated {n}");
        }
        // Trailing zero bytes are not invisible (the length is hashed).
        let mut z = b.clone();
        z.push(0);
        assert_ne!(checksum(&z), h, "padded {n}");
    }
}

/// The model tests' wavy grid with 5 shapes, its quads kept as polygons.
fn quad_patch(n: usize) -> Dataset {
    let mut polygons = Polygons::default();
    for q in crate::model::tests::patch_quads(n) {
        polygons.push(&q, Some(&q));
    }
    crate::model::tests::patch_with(n, 5)
        .with_polygons(polygons)
        .unwrap()
}

fn labelled_model() -> Model {
    let data = quad_patch(9);
    let markers: Vec<DVec3> = [(0.2, 0.2), (0.8, 0.2), (0.5, 0.5), (0.2, 0.8), (0.8, 0.8)]
        .iter()
        .map(|&(u, v)| DVec3::new(u, v, 0.1 * (3.0f64 * u).sin() * (2.0f64 * v).cos()))
        .collect();
    let names = ["chin", "lip_L", "nose", "brow_R", "brow_L"];
    Model::build(&data, &markers, &BuildConfig::default())
        .unwrap()
        .with_labels(names.iter().map(|s| s.to_string()).collect(), "cm".into())
        .unwrap()
}

#[test]
fn marker_names_unit_and_source_polygons_survive_save_and_load() {
    let model = labelled_model();
    let dir = std::env::temp_dir().join(format!("lgi-labels-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.lgi");
    save(&model, &path).unwrap();
    let back = load(&path).unwrap();
    assert_eq!(back.marker_names(), model.marker_names());
    assert_eq!(back.units(), "cm");
    assert_eq!(back.dataset().polygons(), model.dataset().polygons());
    assert_eq!(back.dataset().polygons().unwrap().num_faces(), 64);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_version_3_file_loads_with_default_names_no_unit_and_no_polygons() {
    let model = labelled_model();
    let dir = std::env::temp_dir().join(format!("lgi-v3-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.lgi");
    save(&model, &path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    // A version 3 file is a version 5 payload without its last two sections (the labels and
    // polygons, then what the build derived).
    let p = model.dataset().polygons().unwrap();
    let names: usize = model.marker_names().iter().map(|n| 8 + n.len()).sum();
    let labels = 8 + names + 8 + 2 + 8 + 3 * 8 + 4 * (p.counts.len() + 2 * p.vertices.len());
    let payload = &bytes[HEADER..bytes.len() - labels - derived_len(&model)];
    let mut v3 = Vec::new();
    v3.extend_from_slice(MAGIC);
    v3.extend_from_slice(&BINS_VERSION.to_le_bytes());
    v3.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    v3.extend_from_slice(&checksum(payload).to_le_bytes());
    v3.extend_from_slice(payload);
    std::fs::write(&path, v3).unwrap();
    let back = load(&path).unwrap();
    assert_eq!(
        back.marker_names(),
        ["m000", "m001", "m002", "m003", "m004"]
    );
    assert_eq!(back.units(), "");
    assert!(back.dataset().polygons().is_none());
    std::fs::remove_dir_all(&dir).ok();
}

/// The bytes of version 5's last section (what the build derived, per bin).
fn derived_len(model: &Model) -> usize {
    model
        .parts()
        .bins
        .iter()
        .map(|b| match b.fit_basis {
            Some(Some(basis)) => {
                8 + 8 + 4 * basis.shapes.len() + 8 + 8 * basis.coefficients().len()
            }
            _ => 8,
        })
        .sum()
}

/// A model whose global fit has low rank and a shape basis: more shapes than the markers' rows
/// (the fit's low-rank form), the last the sum of the first two.
fn basis_model() -> Model {
    let d = crate::model::tests::patch_with(9, 20);
    let (v, s) = (d.num_vertices(), d.num_shapes());
    let mut displacements = d.displacements().to_vec();
    let sum: Vec<f32> = (0..3 * v)
        .map(|i| displacements[i] + displacements[3 * v + i])
        .collect();
    displacements.extend(sum);
    let mut names = d.names().to_vec();
    names.push("sum".into());
    let data = Dataset::new(d.neutral().clone(), displacements, names).unwrap();
    assert_eq!(data.num_shapes(), s + 1);
    let markers: Vec<DVec3> = [(0.2, 0.2), (0.8, 0.2), (0.5, 0.5), (0.2, 0.8), (0.8, 0.8)]
        .iter()
        .map(|&(u, v)| DVec3::new(u, v, 0.1 * (3.0f64 * u).sin() * (2.0f64 * v).cos()))
        .collect();
    Model::build(&data, &markers, &BuildConfig::default()).unwrap()
}

/// Frames on blends of the dataset's shapes 0 and 1, as `model`'s markers.
fn blend_frames(model: &Model) -> Vec<Vec<DVec3>> {
    let d = model.dataset();
    [0.0, 0.3, 0.7, 1.0]
        .iter()
        .map(|&t| {
            let mesh: Vec<DVec3> = (0..d.num_vertices())
                .map(|v| {
                    d.neutral().positions[v]
                        + d.displacement(0, v) * t
                        + d.displacement(1, v) * (1.0 - t)
                })
                .collect();
            model.bundle_positions(&mesh).unwrap()
        })
        .collect()
}

/// Every vertex's bits of a noise-aware solve (the global fit sewn over its shape basis).
fn noise_aware_bits(model: &Model, frames: &[Vec<DVec3>]) -> Vec<u64> {
    let options = crate::model::SolveOptions::new(false, 0, Some(true), Some(0.01));
    crate::model::tests::solve_with(model, frames, &options, None)
        .unwrap()
        .iter()
        .flat_map(|f| {
            f.vertices
                .iter()
                .flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        })
        .collect()
}

#[test]
fn the_fit_basis_is_derived_at_build_saved_and_loaded_bit_for_bit() {
    let model = basis_model();
    let derived = model.parts().bins[0].fit_basis.cloned();
    let Some(Some(basis)) = derived else {
        panic!("the build derived no shape basis: {derived:?}");
    };
    assert!(basis.shapes.len() < model.dataset().num_shapes());
    let back = from_bytes(&to_bytes(&model)).unwrap();
    let loaded = back.parts().bins[0].fit_basis.cloned().flatten().unwrap();
    assert_eq!(loaded.shapes, basis.shapes);
    assert_eq!(loaded.coefficients(), basis.coefficients());
    let frames = blend_frames(&model);
    assert_eq!(
        noise_aware_bits(&back, &frames),
        noise_aware_bits(&model, &frames)
    );
}

#[test]
fn a_version_4_file_loads_and_derives_the_fit_basis_at_load_to_the_same_bits() {
    let model = basis_model();
    let bytes = to_bytes(&model);
    let payload = &bytes[HEADER..bytes.len() - derived_len(&model)];
    let mut v4 = Vec::new();
    v4.extend_from_slice(MAGIC);
    v4.extend_from_slice(&4u32.to_le_bytes());
    v4.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    v4.extend_from_slice(&checksum(payload).to_le_bytes());
    v4.extend_from_slice(payload);
    // A version 4 file saves no basis: the load derives it (not a take's first solve), and
    // saves it from then on.
    let back = from_bytes(&v4).unwrap();
    assert!(matches!(back.parts().bins[0].fit_basis, Some(Some(_))));
    let frames = blend_frames(&model);
    assert_eq!(
        noise_aware_bits(&back, &frames),
        noise_aware_bits(&model, &frames)
    );
    assert_eq!(to_bytes(&back), bytes);
}

#[test]
fn a_saved_fit_basis_that_is_not_one_is_a_format_error() {
    let model = basis_model();
    let mut bytes = to_bytes(&model);
    // The first basis shape index (after the bin's tag and the indices' length) out of range.
    let at = bytes.len() - derived_len(&model) + 16;
    bytes[at..at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let n = bytes.len();
    let sum = checksum(&bytes[HEADER..n]);
    bytes[20..28].copy_from_slice(&sum.to_le_bytes());
    let err = from_bytes(&bytes).unwrap_err().to_string();
    assert!(err.contains("fit's shape basis"), "{err}");
}

#[test]
fn to_bytes_are_the_file_and_from_bytes_solves_bit_identically() {
    let model = labelled_model();
    let dir = std::env::temp_dir().join(format!("lgi-bytes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("m.lgi");
    save(&model, &path).unwrap();
    let bytes = to_bytes(&model);
    assert_eq!(bytes, std::fs::read(&path).unwrap());
    let back = from_bytes(&bytes).unwrap();
    back.sanity_check().unwrap();
    assert_eq!(back.marker_names(), model.marker_names());
    assert_eq!(back.units(), model.units());
    assert_eq!(to_bytes(&back), bytes);
    // Frames between the dataset's shapes: the markers on blends of shapes 1 and 2.
    let frames = blend_frames(&model);
    let exact = crate::model::SolveOptions::default();
    let a = crate::model::tests::solve_with(&model, &frames, &exact, None).unwrap();
    let b = crate::model::tests::solve_with(&back, &frames, &exact, None).unwrap();
    for (fa, fb) in a.iter().zip(&b) {
        let bits = |f: &crate::model::tests::Solved| {
            f.vertices
                .iter()
                .flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(fa), bits(fb));
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn corrupt_truncated_or_foreign_bytes_are_model_format_errors_naming_memory() {
    let bytes = to_bytes(&labelled_model());
    let mut flipped = bytes.clone();
    flipped[HEADER + 100] ^= 0x10;
    let dataset = dataset_to_bytes(labelled_model().dataset());
    let cases: [(&[u8], &str); 5] = [
        (&flipped, "checksum mismatch"),
        (&bytes[..bytes.len() - 1], "truncated"),
        (&bytes[..10], "bad magic"),
        (b"", "bad magic"),
        (&dataset, "bad magic"),
    ];
    for (b, why) in cases {
        let Err(e) = from_bytes(b) else {
            panic!("{why}: loaded")
        };
        assert!(matches!(e, LgiError::ModelFormat { .. }), "{why}: {e}");
        let msg = e.to_string();
        assert!(msg.contains(why) && msg.contains(IN_MEMORY), "{why}: {msg}");
    }
}

#[test]
fn a_dataset_round_trips_through_bytes_with_its_polygons_and_refuses_corruption() {
    let d = quad_patch(9);
    let bytes = dataset_to_bytes(&d);
    let back = dataset_from_bytes(&bytes).unwrap();
    assert_eq!(back.neutral(), d.neutral());
    assert_eq!(back.names(), d.names());
    assert_eq!(back.displacements(), d.displacements());
    assert_eq!(back.polygons(), d.polygons());
    let mut flipped = bytes.clone();
    flipped[HEADER + 8] ^= 1;
    let model = to_bytes(&labelled_model());
    for (b, why) in [
        (&flipped[..], "checksum mismatch"),
        (&bytes[..HEADER + 3], "truncated"),
        (&model[..], "bad magic"),
    ] {
        let e = dataset_from_bytes(b).err().map(|e| e.to_string());
        assert!(
            e.as_deref().is_some_and(|m| m.contains(why)),
            "{why}: {e:?}"
        );
    }
}

#[test]
fn version_2_checksum_is_byte_wise_fnv1a() {
    // FNV-1a 64 test vectors.
    assert_eq!(checksum_v2(b""), 0xcbf2_9ce4_8422_2325);
    assert_eq!(checksum_v2(b"a"), 0xaf63_dc4c_8601_ec8c);
    assert_eq!(checksum_v2(b"foobar"), 0x8594_4171_f739_67e8);
}
