//! The LGI model: everything precomputed from a dataset and a marker layout (bundle clouds,
//! tets and their grid indices, UV sewing weights), immutable after build and `Send + Sync`,
//! so frames are solved with `&self` in parallel (rayon over bundles, then over vertices).
//!
//! The rooms: `config` (build parameters), [`lookup`] (jaw-bin lookups and the shape-id
//! spaces), `build` (build and assembly), `parts` (what a saved model is made of), `pose`
//! (each frame's jaw pose), `solve` (the solve and its pipelines), `sanity` (the invariants
//! of a model's parts) and `frame` (what a solve returns). A solve goes down the layers once:
//! `pose` gives each frame's jaw pose, `solve` checks the targets and maps them into the jaw
//! bin, the choice is [`choose`](crate::choose)'s over the bin's tet indices, then one call
//! into [`sew`](crate::sew) (plan and sewing pass, the jaw map applied inside it) writes the
//! vertices.

use crate::choose::AliasGroups;
use crate::cloud::BundleCloud;
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::jaw::{JawBins, JawParams, JawRig};
use crate::mesh::SurfacePoint;
use crate::sew::SewPlans;
use crate::sparse::SparseWeights;
use crate::tet_index::TetIndex;
use crate::uvspace::SewingSpace;
use glam::DVec3;
use std::sync::{Arc, OnceLock};

mod build;
mod config;
mod frame;
mod labels;
pub mod lookup;
mod parts;
mod pose;
mod prepare;
mod residuals;
mod sanity;
mod solve;
#[cfg(test)]
pub(crate) mod tests;

pub use config::BuildConfig;
pub use frame::{FrameInfo, FrameState};
pub use labels::{default_marker_names, MAX_UNIT_LEN};
pub use lookup::{LocalShapeId, Lookup, ShapeId};
pub use parts::{BinParts, BinPartsRef, ModelParts, ModelPartsRef, PartsError};
pub use pose::JawPose;
pub use residuals::FitResiduals;
pub use solve::{Sewn, SolveOptions};

/// Jaw articulation of a model (paper Eq. 2): the rig, each dataset shape's jaw parameters
/// (its jaw motion is unskinned before indexing) and each bundle's jaw weight.
#[derive(Debug, Clone)]
pub struct JawSetup {
    /// What the model was built with: the rig, the shapes' jaw poses and the bins.
    pub input: JawInput,
    /// Jaw weight of every bundle (barycentric blend of its triangle's vertex weights).
    pub bundle_weights: Vec<f64>,
}

/// The jaw part of a build: the rig, every dataset shape's jaw pose, and optionally bins of
/// jaw opening (each with its own point clouds, shapes unskinned to the bin's reference).
#[derive(Debug, Clone)]
pub struct JawInput {
    /// Two-bone skinning rig.
    pub rig: JawRig,
    /// Jaw parameters θ_k of every dataset shape.
    pub shape_thetas: Vec<JawParams>,
    /// Jaw-opening bins (`None`: unbinned).
    pub bins: Option<JawBins>,
}

/// Per-bundle statistics of a built model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BundleStats {
    /// Distinct points in the cloud.
    pub points: usize,
    /// Tets in the index.
    pub tets: usize,
    /// Bytes of the index.
    pub index_bytes: usize,
}

/// A built model. See the module docs.
#[derive(Debug)]
pub struct Model {
    /// The dataset as given (what `dataset()` returns and what is saved).
    dataset: Arc<Dataset>,
    jaw: Option<JawSetup>,
    config: BuildConfig,
    markers_rest: Vec<DVec3>,
    bundles: Vec<SurfacePoint>,
    diagonal: f64,
    /// One per jaw bin (one when unbinned); everything else is shared by the bins.
    lookups: Vec<Lookup>,
    /// Natural neighbours of each bundle (UV Delaunay, not across holes): the choice's score.
    neighbours: Vec<Vec<u32>>,
    /// The sewing weights: the full plan and the plans of missing-bundle sets.
    sewing: SewPlans,
    /// Each marker's label (B) and the length unit of the coordinates (`labels.rs`).
    labels: labels::Labels,
    /// The dataset's blendshape fit at the bundles that starts [`JawPose::Fit`], made on
    /// first use.
    rest_fit: OnceLock<pose::RestFit>,
}

impl Model {
    /// Bundle surface positions on a mesh with the neutral's topology.
    pub fn bundle_positions(&self, positions: &[DVec3]) -> Result<Vec<DVec3>> {
        let nv = self.dataset.num_vertices();
        if positions.len() != nv {
            return Err(LgiError::Input(format!(
                "mesh has {} vertices, the model's neutral has {nv}",
                positions.len()
            )));
        }
        let tris = &self.dataset.neutral().triangles;
        Ok(self
            .bundles
            .iter()
            .map(|sp| sp.evaluate(tris, positions))
            .collect())
    }

    /// The dataset the model was built from.
    pub fn dataset(&self) -> &Dataset {
        &self.dataset
    }
    /// The jaw setup, when the model was built with a jaw rig.
    pub fn jaw(&self) -> Option<&JawSetup> {
        self.jaw.as_ref()
    }
    /// The dataset, shared.
    pub fn dataset_shared(&self) -> Arc<Dataset> {
        self.dataset.clone()
    }
    /// The build configuration.
    pub fn config(&self) -> &BuildConfig {
        &self.config
    }
    /// Marker rest positions as given.
    pub fn markers_rest(&self) -> &[DVec3] {
        &self.markers_rest
    }
    /// Bundles' closest points on the neutral.
    pub fn bundles(&self) -> &[SurfacePoint] {
        &self.bundles
    }
    /// Number of bundles B.
    pub fn num_bundles(&self) -> usize {
        self.bundles.len()
    }
    /// Bounding-box diagonal of the neutral.
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }
    /// Natural neighbours of each bundle (UV Delaunay, not across holes).
    pub fn neighbours(&self) -> &[Vec<u32>] {
        &self.neighbours
    }
    /// Full sewing weights (V × B, every bundle present).
    pub fn sew_weights(&self) -> &SparseWeights {
        self.sewing.full_weights()
    }
    /// The sewing space (chart UVs, proxies, barriers).
    pub fn sewing_space(&self) -> &SewingSpace {
        self.sewing.space()
    }
    /// Per-bundle cloud, tet and memory statistics, summed over the jaw bins.
    pub fn bundle_stats(&self) -> Vec<BundleStats> {
        let mut out = vec![
            BundleStats {
                points: 0,
                tets: 0,
                index_bytes: 0,
            };
            self.bundles.len()
        ];
        for lk in &self.lookups {
            for ((o, c), i) in out.iter_mut().zip(&lk.clouds).zip(&lk.indices) {
                o.points += c.points.len();
                o.tets += i.num_tets();
                o.index_bytes += i.memory_bytes();
            }
        }
        out
    }
    /// The per-bin lookup structures (one when the model is unbinned).
    pub fn lookups(&self) -> &[Lookup] {
        &self.lookups
    }
    /// Clouds of all bundles (of the first jaw bin; the only one when unbinned).
    pub fn clouds(&self) -> &[BundleCloud] {
        &self.lookups[0].clouds
    }
    /// Alias groups of every bundle's cloud points (see [`alias_groups`](crate::choose::alias_groups); first jaw bin).
    pub fn alias_groups(&self) -> &[Vec<AliasGroups>] {
        &self.lookups[0].groups
    }
    /// Tet indices of all bundles (first jaw bin).
    pub fn indices(&self) -> &[TetIndex] {
        &self.lookups[0].indices
    }
    /// Bundle surface positions on every shape, `(S + 1) × B` (index `[k * B + n]`, shape id
    /// 0 the neutral; first jaw bin): what [`Scoring`](crate::choose::Scoring) needs to score candidates outside a
    /// full solve.
    pub fn shape_positions(&self) -> &[DVec3] {
        &self.lookups[0].shape_positions
    }
}
