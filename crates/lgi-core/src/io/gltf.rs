//! glTF 2.0 reader (`.gltf` with embedded or external buffers, or `.glb`): the first mesh is
//! the neutral and its morph targets are the shapes, which glTF already stores as
//! displacements. Node transforms are ignored: the mesh is taken in its own space. The `gltf`
//! crate trusts its input in places (asserts, `unreachable!`, unchecked indices), so every
//! accessor is checked before it is read and any panic left is caught here, at the boundary.

use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::mesh::Mesh;
use glam::{DVec2, DVec3};
use std::path::Path;

/// Reads the first mesh of a glTF/GLB file as a [`Dataset`].
///
/// All triangle primitives of that mesh are merged (vertices concatenated). `TEXCOORD_0`
/// becomes the UVs with UV index == vertex index, v flipped to OBJ's convention (up the
/// image, as every dataset's UVs are); either every primitive has it or none.
/// Missing indices mean sequential triangles. Morph targets become shapes (a target without
/// positions is a zero displacement); names come from the mesh's `extras.targetNames` when
/// present, else `target{k}`. Every error names the file; a file the `gltf` crate cannot
/// parse without panicking is an [`LgiError::Io`] ("cannot read"), never a panic.
pub fn read_gltf(path: &Path) -> Result<Dataset> {
    std::panic::catch_unwind(|| read_gltf_unguarded(path)).unwrap_or_else(|panic| {
        let why = super::panic_message(panic.as_ref());
        Err(LgiError::Io {
            path: path.to_path_buf(),
            message: format!("malformed glTF (the glTF parser failed: {why})"),
        })
    })
}

/// [`read_gltf`] without the panic guard.
fn read_gltf_unguarded(path: &Path) -> Result<Dataset> {
    let bytes = std::fs::read(path).map_err(|e| LgiError::io(path, &e))?;
    let parse_error = |e: gltf::Error| match e {
        gltf::Error::Io(io) => LgiError::io(path, &io),
        other => LgiError::parse(path, 0, format!("not a readable glTF file: {other}")),
    };
    // gltf's own validation indexes accessors unchecked: check the indices first.
    let unchecked = gltf::Gltf::from_slice_without_validation(&bytes).map_err(parse_error)?;
    check_indices(unchecked.document.as_json()).map_err(|m| LgiError::parse(path, 0, m))?;
    let gltf = gltf::Gltf::from_slice(&bytes).map_err(parse_error)?;
    let buffers =
        gltf::import_buffers(&gltf.document, path.parent(), gltf.blob).map_err(parse_error)?;
    let doc = gltf.document;
    let bad = |msg: String| LgiError::parse(path, 0, msg);
    let gmesh = doc
        .meshes()
        .next()
        .ok_or_else(|| bad("the file contains no mesh".into()))?;

    let mut mesh = Mesh::default();
    // Per target, the displacements of all vertices so far (V * 3).
    let mut targets: Vec<Vec<f32>> = Vec::new();
    let mut with_uvs: Option<bool> = None;
    for (pi, prim) in gmesh.primitives().enumerate() {
        if prim.mode() != gltf::mesh::Mode::Triangles {
            return Err(bad(format!(
                "primitive {pi} has mode {:?}; only triangle lists are supported",
                prim.mode()
            )));
        }
        check_accessors(&prim, &buffers).map_err(|m| bad(format!("primitive {pi}: {m}")))?;
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let base = mesh.positions.len();
        let positions = reader
            .read_positions()
            .ok_or_else(|| bad(format!("primitive {pi} has no POSITION attribute")))?;
        mesh.positions
            .extend(positions.map(|p| DVec3::from(p.map(f64::from))));
        let n = mesh.positions.len() - base;

        let uvs = reader.read_tex_coords(0).map(|t| t.into_f32());
        if *with_uvs.get_or_insert(uvs.is_some()) != uvs.is_some() {
            return Err(bad(format!(
                "primitive {pi} {} TEXCOORD_0 but primitive 0 {}; either all or none must",
                if uvs.is_some() { "has" } else { "lacks" },
                if uvs.is_some() { "lacks it" } else { "has it" },
            )));
        }
        if let Some(uvs) = uvs {
            // glTF's v runs down the image, the dataset's (OBJ's) up.
            mesh.uvs
                .extend(uvs.map(|[u, v]| DVec2::new(f64::from(u), 1.0 - f64::from(v))));
            if mesh.uvs.len() != mesh.positions.len() {
                return Err(bad(format!(
                    "primitive {pi}: TEXCOORD_0 count differs from POSITION count"
                )));
            }
        }

        let indices: Vec<u32> = match reader.read_indices() {
            Some(ix) => ix.into_u32().collect(),
            None => (0..n as u32).collect(),
        };
        if indices.len() % 3 != 0 {
            return Err(bad(format!(
                "primitive {pi} has {} indices, not a multiple of 3",
                indices.len()
            )));
        }
        if let Some(&i) = indices.iter().find(|&&i| i as usize >= n) {
            return Err(bad(format!(
                "primitive {pi}: index {i} out of range ({n} vertices)"
            )));
        }
        let base32 = u32::try_from(base).map_err(|_| bad("more than 2^32 vertices".into()))?;
        let first_tri = mesh.triangles.len();
        mesh.triangles.extend(
            indices
                .chunks_exact(3)
                .map(|c| [c[0] + base32, c[1] + base32, c[2] + base32]),
        );
        if with_uvs == Some(true) {
            let new = mesh.triangles[first_tri..].to_vec();
            mesh.uv_triangles.extend(new);
        }

        let mut k = 0;
        for (target_positions, _normals, _tangents) in reader.read_morph_targets() {
            if pi == 0 {
                targets.push(vec![0.0; base * 3]);
            }
            let disp = targets.get_mut(k).ok_or_else(|| {
                bad(format!(
                    "primitive {pi} has more morph targets than primitive 0"
                ))
            })?;
            match target_positions {
                Some(d) => disp.extend(d.flatten()),
                None => disp.resize(disp.len() + n * 3, 0.0),
            }
            if disp.len() != mesh.positions.len() * 3 {
                return Err(bad(format!(
                    "primitive {pi}, morph target {k}: displacement count differs from POSITION count"
                )));
            }
            k += 1;
        }
        if k != targets.len() {
            return Err(bad(format!(
                "primitive {pi} has {k} morph targets, primitive 0 has {}",
                targets.len()
            )));
        }
    }

    let names = target_names(&gmesh, targets.len()).map_err(bad)?;
    let what = path.display().to_string();
    mesh.validate(&what)?;
    Dataset::new(mesh, targets.concat(), names).map_err(|e| match e {
        LgiError::Dataset(m) => LgiError::Dataset(format!("{what}: {m}")),
        other => other,
    })
}

/// Checks the indices between the document's arrays that gltf's validation follows without
/// a bounds check (attributes, indices and targets to accessors, accessors and sparse parts
/// to buffer views, views to buffers).
fn check_indices(root: &gltf::json::Root) -> std::result::Result<(), String> {
    let (na, nv, nb) = (
        root.accessors.len(),
        root.buffer_views.len(),
        root.buffers.len(),
    );
    let check = |what: String, i: usize, n: usize, of: &str| {
        if i < n {
            Ok(())
        } else {
            Err(format!("{what} refers to {of} {i}, but the file has {n}"))
        }
    };
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let at = |x: &str| format!("mesh {m}, primitive {p}: {x}");
            for (semantic, a) in &prim.attributes {
                check(
                    at(&format!("attribute {semantic:?}")),
                    a.value(),
                    na,
                    "accessor",
                )?;
            }
            if let Some(a) = prim.indices {
                check(at("indices"), a.value(), na, "accessor")?;
            }
            for (k, t) in prim.targets.iter().flatten().enumerate() {
                for a in [t.positions, t.normals, t.tangents].into_iter().flatten() {
                    check(at(&format!("morph target {k}")), a.value(), na, "accessor")?;
                }
            }
        }
    }
    for (i, a) in root.accessors.iter().enumerate() {
        if let Some(v) = a.buffer_view {
            check(format!("accessor {i}"), v.value(), nv, "buffer view")?;
        }
        if let Some(s) = &a.sparse {
            check(
                format!("accessor {i} (sparse indices)"),
                s.indices.buffer_view.value(),
                nv,
                "buffer view",
            )?;
            check(
                format!("accessor {i} (sparse values)"),
                s.values.buffer_view.value(),
                nv,
                "buffer view",
            )?;
        }
    }
    for (i, v) in root.buffer_views.iter().enumerate() {
        check(format!("buffer view {i}"), v.buffer.value(), nb, "buffer")?;
    }
    Ok(())
}

/// Checks every accessor a primitive's reading touches against what the `gltf` reader assumes
/// (it asserts or panics otherwise): the component and element types of indices, positions,
/// UVs and morph-target positions, a non-zero count, and a byte stride and range that fit
/// the buffer view and the buffer (a sparse accessor's own index and value views are left
/// to the reader and the panic guard).
fn check_accessors(
    prim: &gltf::Primitive<'_>,
    buffers: &[gltf::buffer::Data],
) -> std::result::Result<(), String> {
    use gltf::accessor::{DataType as T, Dimensions as D};
    use gltf::Semantic;
    let mut used: Vec<(String, gltf::Accessor<'_>, &[T], D)> = Vec::new();
    if let Some(a) = prim.indices() {
        used.push(("indices".into(), a, &[T::U8, T::U16, T::U32], D::Scalar));
    }
    if let Some(a) = prim.get(&Semantic::Positions) {
        used.push(("POSITION".into(), a, &[T::F32], D::Vec3));
    }
    if let Some(a) = prim.get(&Semantic::TexCoords(0)) {
        used.push(("TEXCOORD_0".into(), a, &[T::U8, T::U16, T::F32], D::Vec2));
    }
    for (k, t) in prim.morph_targets().enumerate() {
        if let Some(a) = t.positions() {
            used.push((format!("morph target {k} POSITION"), a, &[T::F32], D::Vec3));
        }
    }
    for (what, a, types, dims) in used {
        let at = || format!("{what} (accessor {})", a.index());
        if !types.contains(&a.data_type()) || a.dimensions() != dims {
            return Err(format!(
                "{} is {:?} {:?}; expected {dims:?} of {types:?}",
                at(),
                a.dimensions(),
                a.data_type()
            ));
        }
        if a.count() == 0 {
            return Err(format!("{} has no elements", at()));
        }
        let Some(view) = a.view() else {
            continue; // no view: the reader reports the attribute as absent
        };
        let size = a.size();
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            return Err(format!(
                "{}: byteStride {stride} is smaller than its element ({size} bytes)",
                at()
            ));
        }
        let end = (a.count() - 1)
            .checked_mul(stride)
            .and_then(|e| e.checked_add(size))
            .and_then(|e| e.checked_add(a.offset()));
        let buffer_len = buffers.get(view.buffer().index()).map_or(0, |b| b.0.len());
        let view_end = view.offset().checked_add(view.length());
        if end.is_none_or(|e| e > view.length()) || view_end.is_none_or(|e| e > buffer_len) {
            return Err(format!(
                "{} reaches past the end of its buffer view or buffer",
                at()
            ));
        }
    }
    Ok(())
}

/// Morph-target names from the de-facto convention `mesh.extras.targetNames`.
fn target_names(mesh: &gltf::Mesh<'_>, count: usize) -> std::result::Result<Vec<String>, String> {
    let default = || (0..count).map(|k| format!("target{k}")).collect();
    let Some(raw) = mesh.extras() else {
        return Ok(default());
    };
    let extras: gltf::json::Value = gltf::json::deserialize::from_str(raw.get())
        .map_err(|e| format!("mesh extras are not valid JSON: {e}"))?;
    let Some(list) = extras.get("targetNames") else {
        return Ok(default());
    };
    let names: Vec<String> = list
        .as_array()
        .and_then(|a| a.iter().map(|v| v.as_str().map(String::from)).collect())
        .ok_or("mesh extras.targetNames is not a list of strings")?;
    if names.len() != count {
        return Err(format!(
            "mesh extras.targetNames has {} names for {count} morph targets",
            names.len()
        ));
    }
    Ok(names)
}
