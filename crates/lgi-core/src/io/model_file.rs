//! Saved models (`.lgi`): a versioned little-endian binary file holding what is expensive to
//! rebuild (dataset, markers, config, per-bundle clouds and tets). Everything cheap (grid
//! indices, correspondences, sewing weights) is recomputed on load. A checksum over the payload
//! turns truncation and corruption into a clear error instead of a wrong model.
//!
//! Versions: 2 (no jaw bins), 3 (jaw bins), 4 (this build: + marker names, unit, the neutral's
//! source polygons). Older files still load: default names `m000…`, no unit, no polygons.
//!
//! The same bytes travel in memory ([`to_bytes`] / [`from_bytes`]: what pickling a model
//! ships to another process) with the same checks on the way in. A dataset alone
//! ([`dataset_to_bytes`] / [`dataset_from_bytes`]) is the model format's dataset part (the
//! neutral, shape names, displacements, then the source polygons) in the same framing under
//! its own magic.

use crate::basis::ShapeBasis;
use crate::cloud::BundleCloud;
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::jaw::{JawBins, JawParams, JawRig};
use crate::mesh::Mesh;
use crate::model::{
    BinParts, BinPartsRef, BuildConfig, JawInput, Model, ModelParts, ModelPartsRef, PartsError,
};
use crate::polygons::Polygons;
use crate::tets::Tet;
use glam::{DMat3, DVec2, DVec3};
use std::path::Path;
use std::sync::Arc;

const MAGIC: &[u8; 8] = b"LGIMODEL";
/// The magic of a dataset on its own (the model format's dataset part).
const DATASET_MAGIC: &[u8; 8] = b"LGIDATAS";
/// What errors name as the file when the bytes came from memory, not from a file.
const IN_MEMORY: &str = "<in-memory bytes>";
/// Format version written by this build; readers accept exactly the versions they know.
pub const FORMAT_VERSION: u32 = 5;
/// The oldest version read (no jaw bins: an unbinned model).
const PREVIOUS_VERSION: u32 = 2;
/// The first version with jaw bins (and the word-wise checksum).
const BINS_VERSION: u32 = 3;
const HEADER: usize = 8 + 4 + 8 + 8;

/// FNV-1a 64 over bytes: the checksum of version 2 files (one multiply per byte, ~0.1 s for
/// a 100 MB model).
pub(crate) fn checksum_v2(bytes: &[u8]) -> u64 {
    checksum_v2_from(FNV_OFFSET, bytes)
}

/// FNV-1a 64 offset basis and prime.
const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
const FNV_PRIME: u64 = 0x0000_0100_0000_01b3;

/// The checksum of version 3 files: FNV-1a over little-endian 8-byte words in four
/// interleaved lanes (independent multiplies), the lanes and the tail bytes folded together
/// with the length. Catches truncation and bit rot like byte-wise FNV at ~1/10 of its cost.
pub(crate) fn checksum(bytes: &[u8]) -> u64 {
    let mut lanes = [
        FNV_OFFSET,
        0x8422_2325_cbf2_9ce4,
        0x9ce4_8422_2325_cbf2,
        0x2325_cbf2_9ce4_8422,
    ];
    let mut blocks = bytes.chunks_exact(32);
    for block in &mut blocks {
        for (lane, word) in lanes.iter_mut().zip(block.chunks_exact(8)) {
            let mut w = [0u8; 8];
            w.copy_from_slice(word);
            *lane = (*lane ^ u64::from_le_bytes(w)).wrapping_mul(FNV_PRIME);
        }
    }
    let mut h = (bytes.len() as u64).wrapping_mul(FNV_PRIME);
    for lane in lanes {
        h = (h ^ lane).wrapping_mul(FNV_PRIME);
        h ^= h >> 29;
    }
    checksum_v2_from(h, blocks.remainder())
}

/// Byte-wise FNV-1a continued from `h`.
fn checksum_v2_from(h: u64, bytes: &[u8]) -> u64 {
    bytes
        .iter()
        .fold(h, |h, &b| (h ^ b as u64).wrapping_mul(FNV_PRIME))
}

#[derive(Default)]
struct Writer(Vec<u8>);

impl Writer {
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f64(&mut self, v: f64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u32s(&mut self, v: impl ExactSizeIterator<Item = u32>) {
        self.u64(v.len() as u64);
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn f64s(&mut self, v: impl ExactSizeIterator<Item = f64>) {
        self.u64(v.len() as u64);
        for x in v {
            self.f64(x);
        }
    }
    fn f32s(&mut self, v: &[f32]) {
        self.u64(v.len() as u64);
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn str(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    /// A format error without a position (a section's content, not its bytes, is wrong).
    fn bad(&self, what: &str) -> LgiError {
        LgiError::ModelFormat {
            path: self.path.to_path_buf(),
            message: what.to_string(),
        }
    }
    fn err(&self, what: &str) -> LgiError {
        LgiError::ModelFormat {
            path: self.path.to_path_buf(),
            message: format!("{what} at byte {}", self.at + HEADER),
        }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(self.err("unexpected end of data"));
        };
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u64(&mut self) -> Result<u64> {
        let b = self.take(8)?;
        Ok(u64::from_le_bytes(
            b.try_into().map_err(|_| self.err("short u64"))?,
        ))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_bits(self.u64()?))
    }
    /// A length prefix, checked against the bytes left so a corrupt count cannot allocate.
    fn len(&mut self, elem: usize) -> Result<usize> {
        let n = self.u64()? as usize;
        if n.checked_mul(elem)
            .is_none_or(|b| b > self.bytes.len() - self.at)
        {
            return Err(self.err(&format!("length {n} exceeds the file")));
        }
        Ok(n)
    }
    fn u32s(&mut self) -> Result<Vec<u32>> {
        let n = self.len(4)?;
        let b = self.take(n * 4)?;
        Ok(b.chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
    fn f64s(&mut self) -> Result<Vec<f64>> {
        let n = self.len(8)?;
        let b = self.take(n * 8)?;
        Ok(b.chunks_exact(8)
            .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
            .collect())
    }
    fn f32s(&mut self) -> Result<Vec<f32>> {
        let n = self.len(4)?;
        let b = self.take(n * 4)?;
        Ok(b.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect())
    }
    fn str(&mut self) -> Result<String> {
        let n = self.len(1)?;
        let b = self.take(n)?;
        String::from_utf8(b.to_vec()).map_err(|_| self.err("invalid UTF-8 string"))
    }
}

fn vec3s(v: &[DVec3]) -> impl ExactSizeIterator<Item = f64> + '_ {
    v.iter()
        .flat_map(|p| [p.x, p.y, p.z])
        .collect::<Vec<_>>()
        .into_iter()
}

fn to_vec3s(r: &Reader<'_>, v: Vec<f64>) -> Result<Vec<DVec3>> {
    if v.len() % 3 != 0 {
        return Err(r.err("3D point array length not a multiple of 3"));
    }
    Ok(v.chunks_exact(3)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect())
}

fn to_tris(r: &Reader<'_>, v: Vec<u32>) -> Result<Vec<[u32; 3]>> {
    if v.len() % 3 != 0 {
        return Err(r.err("triangle array length not a multiple of 3"));
    }
    Ok(v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

/// Writes `model` to `path`, replacing it whole or leaving it as it was
/// ([`atomic`](super::atomic)).
pub fn save(model: &Model, path: &Path) -> Result<()> {
    super::atomic::write_bytes(path, &to_bytes(model))
}

/// The bytes [`save`] writes: the whole file, header and checksum included.
pub fn to_bytes(model: &Model) -> Vec<u8> {
    encode(&model.parts(), model.marker_names(), model.units())
}

/// Writes model parts to `path` as [`save`] would, with the default marker names and no unit:
/// for tools and tests that craft files (a crafted file gets a valid checksum, so only
/// [`load`]'s sanity check stands in its way).
pub fn save_parts(parts: &ModelPartsRef<'_>, path: &Path) -> Result<()> {
    let names = crate::model::default_marker_names(parts.markers_rest.len());
    super::atomic::write_bytes(path, &encode(parts, &names, ""))
}

/// The header (magic, version, payload length, checksum) and the payload.
fn framed(magic: &[u8; 8], payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER + payload.len());
    out.extend_from_slice(magic);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&checksum(payload).to_le_bytes());
    out.extend_from_slice(payload);
    out
}

/// The payload of `bytes` after checking magic, version, length and checksum, and its
/// version; `what` names the kind of bytes in the bad-magic message.
fn unframed<'a>(
    bytes: &'a [u8],
    magic: &[u8; 8],
    what: &str,
    source: &Path,
) -> Result<(u32, &'a [u8])> {
    let bad = |m: &str| LgiError::ModelFormat {
        path: source.to_path_buf(),
        message: m.to_string(),
    };
    if bytes.len() < HEADER || &bytes[..8] != magic {
        return Err(bad(&format!("not {what} (bad magic)")));
    }
    let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    if !(PREVIOUS_VERSION..=FORMAT_VERSION).contains(&version) {
        return Err(bad(&format!(
            "format version {version}; this lgi reads versions {PREVIOUS_VERSION} to \
             {FORMAT_VERSION}: rebuild the model"
        )));
    }
    let mut u = [0u8; 8];
    u.copy_from_slice(&bytes[12..20]);
    let len = u64::from_le_bytes(u) as usize;
    u.copy_from_slice(&bytes[20..28]);
    let sum = u64::from_le_bytes(u);
    let payload = &bytes[HEADER..];
    if payload.len() != len {
        return Err(bad(&format!(
            "truncated or padded: {} payload bytes, header says {len}",
            payload.len()
        )));
    }
    let computed = if version == PREVIOUS_VERSION {
        checksum_v2(payload)
    } else {
        checksum(payload)
    };
    if computed != sum {
        return Err(bad("checksum mismatch: the file is corrupt"));
    }
    Ok((version, payload))
}

/// The neutral mesh, the shape names and the displacements (the model format's dataset part).
fn write_dataset(w: &mut Writer, d: &Dataset) {
    let m = d.neutral();
    w.f64s(vec3s(&m.positions));
    w.u32s(
        m.triangles
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .into_iter(),
    );
    w.f64s(
        m.uvs
            .iter()
            .flat_map(|p| [p.x, p.y])
            .collect::<Vec<_>>()
            .into_iter(),
    );
    w.u32s(
        m.uv_triangles
            .iter()
            .flatten()
            .copied()
            .collect::<Vec<_>>()
            .into_iter(),
    );
    w.u64(d.names().len() as u64);
    for n in d.names() {
        w.str(n);
    }
    w.f32s(d.displacements());
}

/// The neutral's source polygons (0 = none; 1 = counts, vertex indices, UV indices).
fn write_polygons(w: &mut Writer, d: &Dataset) {
    match d.polygons() {
        None => w.u64(0),
        Some(p) => {
            w.u64(1);
            w.u32s(p.counts.iter().copied());
            w.u32s(p.vertices.iter().copied());
            w.u32s(p.uvs.iter().copied());
        }
    }
}

/// A dataset as bytes: the model format's dataset part and polygons, framed under their own
/// magic (what pickling an `lgi.Dataset` ships).
pub fn dataset_to_bytes(dataset: &Dataset) -> Vec<u8> {
    let mut w = Writer::default();
    write_dataset(&mut w, dataset);
    write_polygons(&mut w, dataset);
    framed(DATASET_MAGIC, &w.0)
}

/// Reads what [`dataset_to_bytes`] wrote, with the checks of [`Dataset::new`] and
/// [`Dataset::with_polygons`]; every inconsistency is `LgiError::ModelFormat`.
pub fn dataset_from_bytes(bytes: &[u8]) -> Result<Dataset> {
    let source = Path::new(IN_MEMORY);
    guarded(source, || {
        let (_, payload) = unframed(bytes, DATASET_MAGIC, "lgi dataset bytes", source)?;
        let mut r = Reader {
            bytes: payload,
            at: 0,
            path: source,
        };
        let dataset = read_dataset(&mut r)?;
        let dataset = read_polygons(&mut r, dataset)?;
        if r.at != payload.len() {
            return Err(r.bad("trailing bytes after the last section"));
        }
        Ok(dataset)
    })
}

/// Writes a model's parts and labels: the whole file.
fn encode(parts: &ModelPartsRef<'_>, marker_names: &[String], units: &str) -> Vec<u8> {
    let mut w = Writer::default();
    let c = parts.config;
    for x in [
        c.surface_tolerance,
        c.prune_motion,
        c.duplicate_distance,
        c.min_quality,
        c.max_edge,
        c.containment_eps,
        c.temporal_weight,
        c.detour_ratio,
    ] {
        w.f64(x);
    }
    for n in [c.tet_neighbours, c.max_tets, c.projection_candidates] {
        w.u64(n as u64);
    }
    write_dataset(&mut w, parts.dataset);
    w.f64s(vec3s(parts.markers_rest));
    write_clouds(&mut w, &parts.bins[0]);
    // The jaw section: 0 = none; 1 = pivot, vertex weights, shape poses (identity frame, the
    // version 2 layout); 2 (version 3) = pivot, frame (9 values, column-major), vertex
    // weights, shape poses. Identity frames keep layout 1 so their files stay as before.
    match parts.jaw {
        None => w.u64(0),
        Some(j) => {
            let identity = j.rig.frame == DMat3::IDENTITY;
            w.u64(if identity { 1 } else { 2 });
            for x in j.rig.pivot.to_array() {
                w.f64(x);
            }
            if !identity {
                for x in j.rig.frame.to_cols_array() {
                    w.f64(x);
                }
            }
            w.f64s(j.rig.weights.clone().into_iter());
            w.f64s(
                j.shape_thetas
                    .iter()
                    .flat_map(|t| t.to_array())
                    .collect::<Vec<_>>()
                    .into_iter(),
            );
        }
    }
    // Version 3: the jaw bins section (0 = none; 1 = edges, overlap, then the clouds and tets
    // of bins 1.. — bin 0's are the ones above).
    match parts.jaw.and_then(|j| j.bins.as_ref()) {
        None => w.u64(0),
        Some(bins) => {
            w.u64(1);
            w.f64s(bins.edges.clone().into_iter());
            w.f64(bins.overlap);
            for bin in &parts.bins[1..] {
                write_clouds(&mut w, bin);
            }
        }
    }
    // Version 4: the labels section (marker names, unit), then the neutral's source polygons
    // (0 = none; 1 = counts, vertex indices, UV indices).
    w.u64(marker_names.len() as u64);
    for n in marker_names {
        w.str(n);
    }
    w.str(units);
    write_polygons(&mut w, parts.dataset);
    // Version 5: what the build derived from the model alone, per bin: the global fit's shape
    // basis (0 = not derived; 1 = none, the fit has full rank; 2 = the basis shapes, then every
    // shape's coefficients over them).
    for bin in &parts.bins {
        match bin.fit_basis {
            None => w.u64(0),
            Some(None) => w.u64(1),
            Some(Some(basis)) => {
                w.u64(2);
                w.u32s(basis.shapes.iter().map(|&k| k as u32));
                w.f64s(basis.coefficients().iter().copied());
            }
        }
    }
    framed(MAGIC, &w.0)
}

/// Reads a model written by [`save`]; every inconsistency is `LgiError::ModelFormat`, and a
/// model that loads passes [`Model::sanity_check`].
pub fn load(path: &Path) -> Result<Model> {
    guarded(path, || {
        let bytes = std::fs::read(path).map_err(|e| LgiError::io(path, &e))?;
        decode(&bytes, path)
    })
}

/// Reads a model from the bytes [`to_bytes`] gives, with every check of [`load`] (a model
/// from bytes is exactly as valid as one from a file); errors name `<in-memory bytes>`.
pub fn from_bytes(bytes: &[u8]) -> Result<Model> {
    let source = Path::new(IN_MEMORY);
    guarded(source, || decode(bytes, source))
}

/// Runs a reader with a panic guard: the sanity checks run before assembly; the guard is for
/// what they do not foresee.
fn guarded<T>(source: &Path, read: impl FnOnce() -> Result<T>) -> Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(read)).unwrap_or_else(|panic| {
        let why = super::panic_message(panic.as_ref());
        Err(LgiError::ModelFormat {
            path: source.to_path_buf(),
            message: format!("not a valid model (loading it failed: {why})"),
        })
    })
}

/// The neutral, names and displacements [`write_dataset`] wrote, checked by [`Dataset::new`].
fn read_dataset(r: &mut Reader<'_>) -> Result<Dataset> {
    let positions = {
        let v = r.f64s()?;
        to_vec3s(r, v)?
    };
    let triangles = {
        let v = r.u32s()?;
        to_tris(r, v)?
    };
    let uvs = r.f64s()?;
    if uvs.len() % 2 != 0 {
        return Err(r.err("UV array length not a multiple of 2"));
    }
    let uvs = uvs
        .chunks_exact(2)
        .map(|c| DVec2::new(c[0], c[1]))
        .collect();
    let uv_triangles = {
        let v = r.u32s()?;
        to_tris(r, v)?
    };
    let mesh = Mesh {
        positions,
        triangles,
        uvs,
        uv_triangles,
    };
    let num_names = r.len(8)?;
    let names = (0..num_names)
        .map(|_| r.str())
        .collect::<Result<Vec<_>>>()?;
    let displacements = r.f32s()?;
    Dataset::new(mesh, displacements, names).map_err(|e| r.bad(&e.to_string()))
}

/// `dataset` with the polygons [`write_polygons`] wrote, checked by
/// [`Dataset::with_polygons`].
fn read_polygons(r: &mut Reader<'_>, dataset: Dataset) -> Result<Dataset> {
    match r.u64()? {
        0 => Ok(dataset),
        1 => {
            let polygons = Polygons {
                counts: r.u32s()?,
                vertices: r.u32s()?,
                uvs: r.u32s()?,
            };
            dataset
                .with_polygons(polygons)
                .map_err(|e| r.bad(&e.to_string()))
        }
        _ => Err(r.err("unknown polygons section")),
    }
}

/// A model from the bytes of a model file; `source` is the file (or [`IN_MEMORY`]).
fn decode(bytes: &[u8], source: &Path) -> Result<Model> {
    let bad = |m: &str| LgiError::ModelFormat {
        path: source.to_path_buf(),
        message: m.to_string(),
    };
    let (version, payload) = unframed(bytes, MAGIC, "an lgi model file", source)?;
    let mut r = Reader {
        bytes: payload,
        at: 0,
        path: source,
    };
    let mut f = [0.0; 8];
    for x in &mut f {
        *x = r.f64()?;
    }
    let mut n = [0usize; 3];
    for x in &mut n {
        *x = r.u64()? as usize;
    }
    let config = BuildConfig {
        surface_tolerance: f[0],
        prune_motion: f[1],
        duplicate_distance: f[2],
        min_quality: f[3],
        max_edge: f[4],
        containment_eps: f[5],
        temporal_weight: f[6],
        detour_ratio: f[7],
        tet_neighbours: n[0],
        max_tets: n[1],
        projection_candidates: n[2],
    };
    let mut dataset = read_dataset(&mut r)?;
    let markers = {
        let v = r.f64s()?;
        to_vec3s(&r, v)?
    };
    let mut built = vec![read_clouds(&mut r, markers.len())?];
    let jaw = match r.u64()? {
        0 => None,
        layout @ (1 | 2) => {
            if layout == 2 && version == PREVIOUS_VERSION {
                return Err(r.err("jaw frame in a version 2 file"));
            }
            let pivot = DVec3::new(r.f64()?, r.f64()?, r.f64()?);
            let frame = if layout == 2 {
                let mut c = [0.0; 9];
                for x in &mut c {
                    *x = r.f64()?;
                }
                DMat3::from_cols_array(&c)
            } else {
                DMat3::IDENTITY
            };
            let weights = r.f64s()?;
            let t = r.f64s()?;
            if t.len() != 3 * dataset.num_shapes() {
                return Err(bad("jaw section: wrong number of shape poses"));
            }
            let thetas = t
                .chunks_exact(3)
                .map(|c| JawParams::from_array([c[0], c[1], c[2]]))
                .collect();
            let rig = JawRig::with_frame(pivot, weights, frame).map_err(|e| bad(&e.to_string()))?;
            Some(JawInput {
                rig,
                shape_thetas: thetas,
                bins: None,
            })
        }
        _ => return Err(r.err("unknown jaw section")),
    };
    let bins = match version {
        v if v < BINS_VERSION => None,
        _ => match r.u64()? {
            0 => None,
            1 => {
                let edges = r.f64s()?;
                let overlap = r.f64()?;
                let bins = JawBins { edges, overlap };
                bins.validate().map_err(|e| bad(&e.to_string()))?;
                for _ in 1..bins.num_bins() {
                    built.push(read_clouds(&mut r, markers.len())?);
                }
                Some(bins)
            }
            _ => return Err(r.err("unknown jaw bins section")),
        },
    };
    let labels = if version >= 4 {
        let n = r.len(8)?;
        let names = (0..n).map(|_| r.str()).collect::<Result<Vec<_>>>()?;
        let units = r.str()?;
        dataset = read_polygons(&mut r, dataset)?;
        Some((names, units))
    } else {
        None
    };
    if version >= 5 {
        for (bin, part) in built.iter_mut().enumerate() {
            part.fit_basis = match r.u64()? {
                0 => None,
                1 => Some(None),
                2 => {
                    let shapes: Vec<usize> = r.u32s()?.into_iter().map(|k| k as usize).collect();
                    let coefficients = r.f64s()?;
                    let basis = ShapeBasis::from_saved(shapes, coefficients, dataset.num_shapes());
                    // Bin b's shapes are a subset of the dataset's: the parts check the range.
                    Some(Some(basis.ok_or_else(|| {
                        bad(&format!(
                            "bin {bin}: the fit's shape basis is not a valid one"
                        ))
                    })?))
                }
                _ => return Err(r.err("unknown fit basis section")),
            };
        }
    }
    if r.at != payload.len() {
        return Err(bad("trailing bytes after the last section"));
    }
    let jaw = match (jaw, bins) {
        (jaw, None) => jaw,
        (Some(j), Some(bins)) => Some(JawInput {
            bins: Some(bins),
            ..j
        }),
        (None, Some(_)) => return Err(bad("jaw bins without a jaw rig")),
    };
    let parts = ModelParts {
        dataset: Arc::new(dataset),
        jaw,
        config,
        markers_rest: markers,
        bins: built,
    };
    // A file can carry a valid checksum and still be wrong (edited, then re-summed, or
    // written by something else): its parts must pass every invariant of a built model before
    // assembly, and whatever assembly still refuses is a format error too, not a user's.
    parts
        .as_parts_ref()
        .sanity_check()
        .map_err(|m| bad(&format!("not a valid model: {m}")))?;
    let model = Model::from_parts(parts).map_err(|e| match e {
        PartsError::Inconsistent(m) => bad(&m),
        PartsError::Build(e) => bad(&format!("not a valid model: {e}")),
    })?;
    // What the file does not save is derived now, not at a take's first solve.
    model.derive_for_solves();
    match labels {
        None => Ok(model),
        Some((names, units)) => model
            .with_labels(names, units)
            .map_err(|e| bad(&e.to_string())),
    }
}

/// One bin's clouds and tets, bundle after bundle.
fn write_clouds(w: &mut Writer, bin: &BinPartsRef<'_>) {
    for (cloud, tets) in bin.clouds.iter().zip(&bin.tets) {
        w.f64s(vec3s(&cloud.points));
        w.u64(cloud.aliases.len() as u64);
        for a in &cloud.aliases {
            w.u32s(a.iter().copied());
        }
        w.u32s(
            tets.iter()
                .flatten()
                .copied()
                .collect::<Vec<_>>()
                .into_iter(),
        );
    }
}

/// Reads what [`write_clouds`] wrote for `num_bundles` bundles; tets must index their cloud and
/// every point must have an alias (shape ids are checked against the bin's shapes later).
fn read_clouds(r: &mut Reader<'_>, num_bundles: usize) -> Result<BinParts> {
    let mut clouds = Vec::with_capacity(num_bundles);
    let mut tets = Vec::with_capacity(num_bundles);
    for i in 0..num_bundles {
        let points = {
            let v = r.f64s()?;
            to_vec3s(r, v)?
        };
        let na = r.len(8)?;
        let aliases = (0..na).map(|_| r.u32s()).collect::<Result<Vec<_>>>()?;
        let t = r.u32s()?;
        if aliases.len() != points.len() || t.len() % 4 != 0 {
            return Err(r.err(&format!("bundle {i}: inconsistent cloud or tets")));
        }
        let np = points.len() as u32;
        let t: Vec<Tet> = t
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        if t.iter().flatten().any(|&p| p >= np) || aliases.iter().any(|a| a.is_empty()) {
            return Err(r.err(&format!("bundle {i}: index out of range")));
        }
        clouds.push(BundleCloud { points, aliases });
        tets.push(t);
    }
    Ok(BinParts {
        clouds,
        tets,
        fit_basis: None,
    })
}

#[cfg(test)]
mod tests;
