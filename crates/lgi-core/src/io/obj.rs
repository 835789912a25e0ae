//! Wavefront OBJ reader and writer, and datasets from OBJ files. Faces are fan-split into
//! triangles and per-corner UVs are kept (seams survive); the source faces are kept too
//! ([`Polygons`], for exports); parsing works on bytes, line by line,
//! without per-line allocation so the 2.6 MB ICT neutral reads in milliseconds. Errors name the
//! file and the 1-based line.

use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::mesh::Mesh;
use crate::polygons::Polygons;
use glam::{DVec2, DVec3};
use rayon::prelude::*;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Reads an OBJ file into a triangle mesh. See [`parse_obj`] for what is understood.
pub fn read_obj(path: &Path) -> Result<Mesh> {
    read_obj_polygons(path).map(|(mesh, _)| mesh)
}

/// Reads an OBJ file into its triangle mesh and its source faces (quads, n-gons as written),
/// which fan-split into the mesh's triangles.
pub fn read_obj_polygons(path: &Path) -> Result<(Mesh, Polygons)> {
    let bytes = std::fs::read(path).map_err(|e| LgiError::io(path, &e))?;
    parse_obj_bytes(&bytes, path)
}

/// Parses OBJ text (`path` only names the source in errors).
///
/// Understood: `v x y z` (a 4th `w` or colour values are ignored), `vt u v`, and `f` with
/// corners `a`, `a/b`, `a/b/c` or `a//c`, 1-based or negative (relative) indices. Faces with
/// more than 3 corners are fan-split. Normals, groups, smoothing and materials are ignored.
/// Either every face carries UVs or none does; a mix is an error naming the first odd line.
/// The result is validated ([`Mesh::validate`]), so it has vertices and faces.
pub fn parse_obj(text: &str, path: &Path) -> Result<Mesh> {
    parse_obj_bytes(text.as_bytes(), path).map(|(mesh, _)| mesh)
}

/// Reads only the `v` lines of an OBJ file: the fast path for shape files that share the
/// neutral's topology. Fails naming the file when the count differs from `expected_vertices`.
pub fn read_obj_positions(path: &Path, expected_vertices: usize) -> Result<Vec<DVec3>> {
    let bytes = std::fs::read(path).map_err(|e| LgiError::io(path, &e))?;
    let mut positions = Vec::with_capacity(expected_vertices);
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let mut toks = Tokens::new(line);
        if toks.next() == Some(b"v") {
            positions.push(parse_vertex(&mut toks, path, i + 1)?);
        }
    }
    if positions.len() != expected_vertices {
        return Err(LgiError::Dataset(format!(
            "shape file {} has {} vertices, the neutral has {expected_vertices}",
            path.display(),
            positions.len()
        )));
    }
    Ok(positions)
}

impl Dataset {
    /// Loads a dataset from OBJ files: the neutral (topology and UVs) and one OBJ per shape
    /// with the same vertex order. Shapes are read in parallel (only their `v` lines); each
    /// is named after its file stem; the neutral's source faces are kept
    /// ([`Dataset::polygons`]). Errors name the file at fault.
    pub fn from_obj_files(neutral: &Path, shapes: &[PathBuf]) -> Result<Dataset> {
        let (mesh, polygons) = read_obj_polygons(neutral)?;
        let v = mesh.num_vertices();
        let read: Vec<Result<Vec<DVec3>>> = shapes
            .par_iter()
            .map(|p| read_obj_positions(p, v))
            .collect();
        let mut named = Vec::with_capacity(shapes.len());
        // Sequential pass so the error reported is that of the first bad file, every run.
        for (p, r) in shapes.iter().zip(read) {
            let name = p
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .ok_or_else(|| {
                    LgiError::Dataset(format!("shape file {} has no file name", p.display()))
                })?;
            named.push((name, r?));
        }
        // The dataset's own checks (magnitudes, names) name shape and vertex; add the file.
        Dataset::from_shape_positions(mesh, named)
            .map_err(|e| match e {
                LgiError::Dataset(m) => LgiError::Dataset(format!("{}: {m}", neutral.display())),
                other => other,
            })?
            .with_polygons(polygons)
    }
}

/// Writes `positions` with the topology and UVs of `mesh` as OBJ (`v`, `vt`, `f v/vt`).
/// `positions` may differ from `mesh.positions` (e.g. a reconstructed frame) but must have
/// the same length. Numbers are written in shortest round-trip form, so reading back is exact.
pub fn write_obj(path: &Path, positions: &[DVec3], mesh: &Mesh) -> Result<()> {
    if positions.len() != mesh.num_vertices() {
        return Err(LgiError::Input(format!(
            "write_obj {}: {} positions for a mesh of {} vertices",
            path.display(),
            positions.len(),
            mesh.num_vertices()
        )));
    }
    super::atomic::write_with(path, |w| write_obj_to(w, positions, mesh))
}

fn write_obj_to(w: &mut dyn Write, positions: &[DVec3], mesh: &Mesh) -> std::io::Result<()> {
    for p in positions {
        writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
    }
    let uvs = mesh.has_uvs();
    if uvs {
        for t in &mesh.uvs {
            writeln!(w, "vt {} {}", t.x, t.y)?;
        }
    }
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if uvs {
            let u = mesh.uv_triangles[t];
            writeln!(
                w,
                "f {}/{} {}/{} {}/{}",
                tri[0] + 1,
                u[0] + 1,
                tri[1] + 1,
                u[1] + 1,
                tri[2] + 1,
                u[2] + 1
            )?;
        } else {
            writeln!(w, "f {} {} {}", tri[0] + 1, tri[1] + 1, tri[2] + 1)?;
        }
    }
    Ok(())
}

/// Whitespace-separated tokens of one line; `#` starts a comment. Borrowing, no allocation.
struct Tokens<'a> {
    rest: &'a [u8],
}

impl<'a> Tokens<'a> {
    fn new(line: &'a [u8]) -> Self {
        Tokens { rest: line }
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = &'a [u8];

    fn next(&mut self) -> Option<&'a [u8]> {
        let start = self.rest.iter().position(|b| !b.is_ascii_whitespace())?;
        let rest = &self.rest[start..];
        if rest[0] == b'#' {
            self.rest = &[];
            return None;
        }
        let end = rest
            .iter()
            .position(|b| b.is_ascii_whitespace())
            .unwrap_or(rest.len());
        self.rest = &rest[end..];
        Some(&rest[..end])
    }
}

fn show(tok: &[u8]) -> String {
    String::from_utf8_lossy(tok).into_owned()
}

fn parse_f64(tok: &[u8], path: &Path, line: usize, what: &str) -> Result<f64> {
    let x: f64 = std::str::from_utf8(tok)
        .ok()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| {
            LgiError::parse(path, line, format!("bad number '{}' in {what}", show(tok)))
        })?;
    if !x.is_finite() {
        return Err(LgiError::parse(
            path,
            line,
            format!("non-finite coordinate '{}' in {what}", show(tok)),
        ));
    }
    Ok(x)
}

fn parse_vertex(toks: &mut Tokens<'_>, path: &Path, line: usize) -> Result<DVec3> {
    let mut c = [0.0; 3];
    for (i, slot) in c.iter_mut().enumerate() {
        let tok = toks.next().ok_or_else(|| {
            LgiError::parse(
                path,
                line,
                format!("truncated vertex line: {i} of 3 coordinates ('v x y z')"),
            )
        })?;
        *slot = parse_f64(tok, path, line, "vertex")?;
    }
    Ok(DVec3::from_array(c))
}

fn parse_uv(toks: &mut Tokens<'_>, path: &Path, line: usize) -> Result<DVec2> {
    let mut c = [0.0; 2];
    for (i, slot) in c.iter_mut().enumerate() {
        let tok = toks.next().ok_or_else(|| {
            LgiError::parse(
                path,
                line,
                format!("truncated texture-coordinate line: {i} of 2 values ('vt u v')"),
            )
        })?;
        *slot = parse_f64(tok, path, line, "texture coordinate")?;
    }
    Ok(DVec2::from_array(c))
}

/// Parses an OBJ index (1-based, or negative = relative to the `count` elements read so far)
/// into a 0-based index. Positive indices are range-checked at the end of the file, so
/// forward references (legal in some exporters) still work.
fn parse_index(tok: &[u8], count: usize, path: &Path, line: usize, what: &str) -> Result<i64> {
    let bad = || LgiError::parse(path, line, format!("bad {what} index '{}'", show(tok)));
    let (neg, digits) = match tok.first() {
        Some(b'-') => (true, &tok[1..]),
        Some(b'+') => (false, &tok[1..]),
        _ => (false, tok),
    };
    if digits.is_empty() || digits.len() > 12 || !digits.iter().all(u8::is_ascii_digit) {
        return Err(bad());
    }
    let n = digits
        .iter()
        .fold(0i64, |acc, d| acc * 10 + i64::from(d - b'0'));
    if n == 0 {
        return Err(LgiError::parse(
            path,
            line,
            format!("{what} index 0: OBJ indices start at 1"),
        ));
    }
    if neg {
        let i = count as i64 - n;
        if i < 0 {
            return Err(LgiError::parse(
                path,
                line,
                format!("relative {what} index -{n} is out of range: only {count} defined so far"),
            ));
        }
        Ok(i)
    } else {
        Ok(n - 1)
    }
}

/// The largest positive index seen for one element kind, and where, for the final range check.
#[derive(Default)]
struct MaxRef {
    index: i64,
    line: usize,
}

impl MaxRef {
    fn see(&mut self, index: i64, line: usize) {
        if index >= self.index {
            self.index = index;
            self.line = line;
        }
    }

    fn check(&self, count: usize, path: &Path, what: &str, plural: &str) -> Result<()> {
        if self.line > 0 && self.index >= count as i64 {
            return Err(LgiError::parse(
                path,
                self.line,
                format!(
                    "{what} index {} is out of range: the file has {count} {plural}",
                    self.index + 1
                ),
            ));
        }
        Ok(())
    }
}

fn parse_obj_bytes(bytes: &[u8], path: &Path) -> Result<(Mesh, Polygons)> {
    let mut mesh = Mesh::default();
    let mut polygons = Polygons::default();
    // Corners of the current face, reused across lines: (vertex, uv or -1).
    let mut corners: Vec<(i64, i64)> = Vec::with_capacity(8);
    // Whether faces carry UVs, fixed by the first face (with its line for the message).
    let mut face_uvs: Option<(bool, usize)> = None;
    let mut max_v = MaxRef::default();
    let mut max_vt = MaxRef::default();

    for (i, raw) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = i + 1;
        let mut toks = Tokens::new(raw);
        match toks.next() {
            Some(b"v") => mesh.positions.push(parse_vertex(&mut toks, path, line)?),
            Some(b"vt") => mesh.uvs.push(parse_uv(&mut toks, path, line)?),
            Some(b"f") => {
                corners.clear();
                for tok in toks.by_ref() {
                    let mut parts = tok.splitn(3, |&b| b == b'/');
                    let v_tok = parts.next().unwrap_or_default();
                    let v = parse_index(v_tok, mesh.positions.len(), path, line, "vertex")?;
                    max_v.see(v, line);
                    let vt = match parts.next() {
                        Some(t) if !t.is_empty() => {
                            let vt =
                                parse_index(t, mesh.uvs.len(), path, line, "texture coordinate")?;
                            max_vt.see(vt, line);
                            vt
                        }
                        _ => -1,
                    };
                    corners.push((v, vt));
                }
                add_face(
                    &mut mesh,
                    &mut polygons,
                    &corners,
                    &mut face_uvs,
                    path,
                    line,
                )?;
            }
            // Normals, groups, objects, smoothing, materials, comments, blank lines, and
            // anything else (curves, lines): not needed for a face mesh.
            _ => {}
        }
    }
    max_v.check(mesh.positions.len(), path, "vertex", "vertices")?;
    max_vt.check(
        mesh.uvs.len(),
        path,
        "texture coordinate",
        "texture coordinates",
    )?;
    if matches!(face_uvs, Some((false, _)) | None) {
        mesh.uvs.clear();
    }
    let what = path.display().to_string();
    mesh.validate(&what)?;
    Ok((mesh, polygons))
}

fn add_face(
    mesh: &mut Mesh,
    polygons: &mut Polygons,
    corners: &[(i64, i64)],
    face_uvs: &mut Option<(bool, usize)>,
    path: &Path,
    line: usize,
) -> Result<()> {
    if corners.len() < 3 {
        return Err(LgiError::parse(
            path,
            line,
            format!("face with {} corners (at least 3 needed)", corners.len()),
        ));
    }
    let with_uv = corners.iter().filter(|c| c.1 >= 0).count();
    if with_uv != 0 && with_uv != corners.len() {
        return Err(LgiError::parse(
            path,
            line,
            "face mixes corners with and without texture coordinates",
        ));
    }
    let has_uv = with_uv != 0;
    match *face_uvs {
        None => *face_uvs = Some((has_uv, line)),
        Some((first, first_line)) if first != has_uv => {
            let this = if has_uv {
                format!(
                    "this face has texture coordinates but the face on line {first_line} has none"
                )
            } else {
                format!(
                    "this face has no texture coordinates but the face on line {first_line} has"
                )
            };
            return Err(LgiError::parse(
                path,
                line,
                format!("{this}; either every face must have UVs or none"),
            ));
        }
        Some(_) => {}
    }
    for (k, a) in corners.iter().enumerate() {
        if corners[k + 1..].iter().any(|b| b.0 == a.0) {
            return Err(LgiError::parse(
                path,
                line,
                format!("face repeats vertex {}", a.0 + 1),
            ));
        }
    }
    // Indices fit in u32: they are < 10^12 by parsing and checked against the counts later;
    // larger counts than u32 cannot occur in a mesh we can hold.
    let to_u32 = |i: i64| u32::try_from(i).unwrap_or(u32::MAX);
    // The source face, in corner order (no allocation: pushed straight into the flat lists).
    polygons.counts.push(corners.len() as u32);
    polygons
        .vertices
        .extend(corners.iter().map(|c| to_u32(c.0)));
    if has_uv {
        polygons.uvs.extend(corners.iter().map(|c| to_u32(c.1)));
    }
    let c0 = corners[0];
    for w in corners[1..].windows(2) {
        let (c1, c2) = (w[0], w[1]);
        mesh.triangles
            .push([to_u32(c0.0), to_u32(c1.0), to_u32(c2.0)]);
        if has_uv {
            mesh.uv_triangles
                .push([to_u32(c0.1), to_u32(c1.1), to_u32(c2.1)]);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Mesh> {
        parse_obj(text, Path::new("t.obj"))
    }

    #[test]
    fn quad_with_uvs_is_fan_split_keeping_uv_corners() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n")
            .unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.uv_triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(m.uvs[2], DVec2::new(1.0, 1.0));
    }

    #[test]
    fn source_faces_are_kept_and_fan_split_into_the_triangles() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.5\nf 1/1 2/2 3/3 4/4\nf 2/2 5/5 6/1 3/3\nf 2/2 3/3 6/4\n";
        let (m, p) = parse_obj_bytes(text.as_bytes(), Path::new("t.obj")).unwrap();
        assert_eq!(p.counts, vec![4, 4, 3]);
        assert_eq!(p.vertices, vec![0, 1, 2, 3, 1, 4, 5, 2, 1, 2, 5]);
        assert_eq!(p.uvs, vec![0, 1, 2, 3, 1, 4, 0, 2, 1, 2, 3]);
        assert_eq!(m.triangles.len(), 5);
        p.check_against(&m, "t.obj").unwrap();
    }

    #[test]
    fn comments_crlf_and_extra_vertex_values_are_tolerated() {
        let m = parse("# c\r\nv 0 0 0 1 # w\r\nv 1 0 0 0.5 0.5 0.5\r\nv 0 1 0\r\nvn 0 0 1\r\ns off\r\nf 1//1 2//1 3//1\r\n")
            .unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        assert!(!m.has_uvs() && m.uvs.is_empty());
    }

    #[test]
    fn forward_references_are_accepted_and_checked_at_the_end() {
        let m = parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        let e = parse("f 1 2 4\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap_err();
        assert!(matches!(e, LgiError::Parse { line: 1, .. }), "{e}");
    }

    #[test]
    fn writer_output_reads_back_exactly() {
        let m = parse("v 0.1 0.2 0.3\nv 1e-7 0 0\nv 0 1 -2.5\nv 3 3 3\nvt 0.25 0.5\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/2\n")
            .unwrap();
        let mut buf = Vec::new();
        write_obj_to(&mut buf, &m.positions, &m).unwrap();
        let back = parse(std::str::from_utf8(&buf).unwrap()).unwrap();
        assert_eq!(back, m);
    }
}
