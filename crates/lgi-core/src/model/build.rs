//! Building a model: bundles located on the neutral, per jaw bin the bundle clouds and their
//! tets (the expensive part, which a saved model stores), then the cheap assembly shared with
//! loading (tet indices, alias groups, sewing weights, the bundles' jaw weights).

use super::lookup::{lookup_sources, Lookup, LookupParts, LookupSource};
use super::{labels, BuildConfig, JawInput, JawSetup, Model};
use crate::cloud::{build_cloud, BundleCloud};
use crate::correspond::correspond;
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::mesh::Mesh;
use crate::mesh::SurfacePoint;
use crate::sew::{SewGeometry, SewPlans};
use crate::tets::{generate_tets, Tet, TetConfig};
use glam::DVec3;
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

impl Model {
    /// Builds the model for `dataset` and marker rest positions `markers_rest` (B).
    pub fn build(dataset: &Dataset, markers_rest: &[DVec3], config: &BuildConfig) -> Result<Model> {
        Model::build_shared(Arc::new(dataset.clone()), markers_rest, config, None)
    }

    /// As [`Model::build`], sharing the dataset instead of copying it, with an optional jaw
    /// (rig, the dataset shapes' jaw parameters — their jaw motion is unskinned first — and
    /// optional jaw-opening bins, each with its own clouds).
    pub fn build_shared(
        dataset: Arc<Dataset>,
        markers_rest: &[DVec3],
        config: &BuildConfig,
        jaw: Option<JawInput>,
    ) -> Result<Model> {
        config.validate()?;
        let sources = lookup_sources(&dataset, jaw.as_ref())?;
        let mesh = dataset.neutral();
        let b = markers_rest.len();
        if b < 3 {
            return Err(LgiError::Input(format!(
                "need at least 3 markers to sew, got {b}"
            )));
        }
        let diagonal = mesh.diagonal();
        let bundles = locate_bundles(mesh, markers_rest, config)?;
        let tet_cfg = TetConfig {
            neighbours: config.tet_neighbours,
            max_tets: config.max_tets,
            min_quality: config.min_quality,
            max_edge: config.max_edge * diagonal,
        };
        let mut parts = Vec::with_capacity(sources.len());
        for source in sources {
            let shape_positions =
                lookup_bundle_positions(&dataset, &source, &bundles, jaw.as_ref())?;
            let s1 = source.num_shapes() + 1;
            let built: Vec<(BundleCloud, Vec<Tet>)> = (0..b)
                .into_par_iter()
                .map(|i| {
                    let pos: Vec<DVec3> = (0..s1).map(|k| shape_positions[k * b + i]).collect();
                    let cloud = build_cloud(
                        &pos,
                        config.prune_motion * diagonal,
                        config.duplicate_distance * diagonal,
                    )?;
                    let tets = generate_tets(&cloud.points, &tet_cfg);
                    Ok((cloud, tets))
                })
                .collect::<Result<_>>()?;
            let (clouds, tets) = built.into_iter().unzip();
            parts.push(LookupParts {
                source,
                shape_positions,
                clouds,
                tets,
                fit_basis: None,
            });
        }
        let model = Model::assemble(dataset, jaw, markers_rest, config, bundles, parts)?;
        model.derive_for_solves();
        Ok(model)
    }

    /// Work that depends only on the model, done when it is built (the fit's shape basis,
    /// seconds at 2,000 scans, is saved with it) or loaded, never at a take's first solve: per
    /// bin the fit's shape basis, where each shape moves per blend block and the fit's solvers'
    /// factors, and with a jaw rig the dataset's fit at rest that a pose from the fit starts
    /// from.
    pub(crate) fn derive_for_solves(&self) {
        let ((), rest) = rayon::join(
            || {
                self.lookups.par_iter().for_each(|lk| {
                    rayon::join(
                        || rayon::join(|| lk.fit_basis(), || lk.shape_spans()),
                        || lk.prior.as_ref().map(|p| p.derive()),
                    );
                })
            },
            || match (&self.jaw, self.rest_fit.get()) {
                (Some(_), None) => super::pose::RestFit::derived(self).ok(),
                _ => None,
            },
        );
        // A rest fit that cannot be made is left to the solve that needs it, whose error
        // names the frame.
        if let Some(made) = rest {
            let _ = self.rest_fit.set(made);
        }
    }

    /// The cheap part of a build, shared with loading a saved model: everything derived from
    /// the dataset, markers, clouds and tets (grid indices, sewing weights, alias groups).
    pub(super) fn assemble(
        dataset: Arc<Dataset>,
        jaw: Option<JawInput>,
        markers_rest: &[DVec3],
        config: &BuildConfig,
        bundles: Vec<SurfacePoint>,
        parts: Vec<LookupParts>,
    ) -> Result<Model> {
        let mesh = dataset.neutral();
        let b = markers_rest.len();
        let diagonal = mesh.diagonal();
        let geometry = SewGeometry::new(mesh, &bundles, config.detour_ratio)?;
        let neighbours = geometry.neighbours(&dataset, &bundles)?;
        let lookups = parts
            .into_iter()
            .map(|part| Lookup::new(part, &neighbours, dataset.num_shapes(), b))
            .collect::<Result<Vec<_>>>()?;
        let sewing = SewPlans::new(geometry, &dataset, &bundles)?;
        let jaw = match jaw {
            None => None,
            Some(input) => {
                let bundle_weights = jaw_bundle_weights(&input, mesh, &bundles)?;
                Some(JawSetup {
                    input,
                    bundle_weights,
                })
            }
        };
        Ok(Model {
            dataset,
            jaw,
            config: config.clone(),
            markers_rest: markers_rest.to_vec(),
            bundles,
            diagonal,
            lookups,
            neighbours,
            sewing,
            labels: labels::Labels::unnamed(markers_rest.len()),
            rest_fit: OnceLock::new(),
        })
    }
}

/// Bundles' closest points on the neutral.
pub(super) fn locate_bundles(
    mesh: &Mesh,
    markers_rest: &[DVec3],
    config: &BuildConfig,
) -> Result<Vec<SurfacePoint>> {
    Ok(correspond(
        mesh,
        markers_rest,
        config.surface_tolerance * mesh.diagonal(),
    )?
    .into_iter()
    .map(|(sp, _)| sp)
    .collect())
}

/// Every bundle's jaw weight: the barycentric blend of its triangle's vertex weights.
pub(super) fn jaw_bundle_weights(
    input: &JawInput,
    mesh: &crate::mesh::Mesh,
    bundles: &[SurfacePoint],
) -> Result<Vec<f64>> {
    bundles
        .iter()
        .map(|b| {
            input
                .rig
                .interpolate_weight(mesh.triangles[b.triangle as usize], b.bary)
        })
        .collect()
}

/// The bundles' positions on a lookup's neutral and member shapes, `(members + 1) × B`, that
/// its clouds, alias groups and fit are built from. With a jaw they are the dataset's own
/// (skinned) bundle positions moved into the lookup's space the way a frame's markers are
/// (`Model::repose_bundles`: each bundle with its interpolated jaw weight, unskinned by the
/// shape's pose, skinned to the bin's reference), so a dataset shape's own markers at its own
/// pose land exactly on its cloud point; sampling the shapes unskinned vertex by vertex would
/// differ where jaw weights blend (the mouth corners, the chin and neck).
pub(super) fn lookup_bundle_positions(
    dataset: &Dataset,
    source: &LookupSource,
    bundles: &[SurfacePoint],
    jaw: Option<&JawInput>,
) -> Result<Vec<DVec3>> {
    let Some(input) = jaw else {
        return Ok(shape_bundle_positions(source.data(), bundles));
    };
    let b = bundles.len();
    let skinned = shape_bundle_positions(dataset, bundles);
    let weights = jaw_bundle_weights(input, dataset.neutral(), bundles)?;
    let rig = &input.rig;
    let mut out = Vec::with_capacity((source.num_shapes() + 1) * b);
    let ids = std::iter::once(None).chain(source.members().iter().map(|&m| Some(m as usize)));
    for member in ids {
        let row = &skinned[member.map_or(0, |m| m + 1) * b..][..b];
        let mut unskinned = row.to_vec();
        if let Some(m) = member {
            rig.unskin_weighted(row, &weights, input.shape_thetas[m], &mut unskinned)?;
        }
        let mut moved = unskinned.clone();
        if let Some(r) = source.reference() {
            rig.skin_weighted(&unskinned, &weights, r, &mut moved)?;
        }
        out.extend(moved);
    }
    Ok(out)
}

/// Bundle positions on every shape, `(S + 1) × B` with shape id 0 the neutral (the
/// dataset's ids, which are the bin-local ids of a lookup built from it).
pub(super) fn shape_bundle_positions(dataset: &Dataset, bundles: &[SurfacePoint]) -> Vec<DVec3> {
    let mesh = dataset.neutral();
    let b = bundles.len();
    let s1 = dataset.num_shapes() + 1;
    let mut out = vec![DVec3::ZERO; s1 * b];
    out.par_chunks_mut(b).enumerate().for_each(|(k, row)| {
        for (i, sp) in bundles.iter().enumerate() {
            let tri = mesh.triangles[sp.triangle as usize];
            let mut p = DVec3::ZERO;
            for (&v, &w) in tri.iter().zip(&sp.bary) {
                let v = v as usize;
                let d = if k == 0 {
                    DVec3::ZERO
                } else {
                    dataset.displacement(k - 1, v)
                };
                p += (mesh.positions[v] + d) * w;
            }
            row[i] = p;
        }
    });
    out
}
