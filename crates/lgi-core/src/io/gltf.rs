//! glTF 2.0 reader (`.gltf` with embedded or external buffers, or `.glb`): the first mesh is
//! the neutral and its morph targets are the shapes, which glTF already stores as
//! displacements. Node transforms are ignored: the mesh is taken in its own space.

use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::mesh::Mesh;
use glam::{DVec2, DVec3};
use std::path::Path;

/// Reads the first mesh of a glTF/GLB file as a [`Dataset`].
///
/// All triangle primitives of that mesh are merged (vertices concatenated). `TEXCOORD_0`
/// becomes the UVs with UV index == vertex index; either every primitive has it or none.
/// Missing indices mean sequential triangles. Morph targets become shapes (a target without
/// positions is a zero displacement); names come from the mesh's `extras.targetNames` when
/// present, else `target{k}`. Every error names the file.
pub fn read_gltf(path: &Path) -> Result<Dataset> {
    let (doc, buffers, _images) = gltf::import(path).map_err(|e| match e {
        gltf::Error::Io(io) => LgiError::io(path, &io),
        other => LgiError::parse(path, 0, format!("not a readable glTF file: {other}")),
    })?;
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
            mesh.uvs.extend(uvs.map(|t| DVec2::from(t.map(f64::from))));
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
