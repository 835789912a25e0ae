//! What a model is made of when it is not a model: the inputs of a build plus the expensive
//! part of it (every bin's bundle clouds and tets). A saved model file serialises exactly this
//! ([`Model::parts`]) and gets a model back from it ([`Model::from_parts`]), which recomputes
//! everything cheap, so the file format never sees the model's internals.

use super::build::{locate_bundles, lookup_bundle_positions};
use super::lookup::{lookup_sources, LookupParts};
use super::{BuildConfig, JawInput, Model};
use crate::basis::ShapeBasis;
use crate::cloud::BundleCloud;
use crate::dataset::Dataset;
use crate::error::LgiError;
use crate::tets::Tet;
use glam::DVec3;
use std::sync::Arc;

/// The parts of a model, owned: what [`Model::from_parts`] assembles a model from.
#[derive(Debug, Clone)]
pub struct ModelParts {
    /// The dataset as given to the build.
    pub dataset: Arc<Dataset>,
    /// The jaw the model was built with (rig, shape poses, bins), if any.
    pub jaw: Option<JawInput>,
    /// The build configuration.
    pub config: BuildConfig,
    /// Marker rest positions (B).
    pub markers_rest: Vec<DVec3>,
    /// Per jaw bin (one when unbinned), in bin order: its clouds and tets.
    pub bins: Vec<BinParts>,
}

/// One jaw bin's built clouds and tets (bin-local shape ids, see [`lookup`](super::lookup)).
#[derive(Debug, Clone)]
pub struct BinParts {
    /// Every bundle's cloud (B).
    pub clouds: Vec<BundleCloud>,
    /// Every bundle's tets, indexing its cloud's points (B).
    pub tets: Vec<Vec<Tet>>,
    /// The global fit's shape basis as derived at build (`Some(None)`: none, the fit has full
    /// rank); `None`: not derived (a file older than version 5), found on first use.
    pub fit_basis: Option<Option<ShapeBasis>>,
}

/// The parts of a model, borrowed from it ([`Model::parts`]): what a saved model stores.
#[derive(Debug, Clone)]
pub struct ModelPartsRef<'a> {
    /// The dataset as given to the build.
    pub dataset: &'a Dataset,
    /// The jaw the model was built with, if any.
    pub jaw: Option<&'a JawInput>,
    /// The build configuration.
    pub config: &'a BuildConfig,
    /// Marker rest positions (B).
    pub markers_rest: &'a [DVec3],
    /// Per jaw bin (one when unbinned), in bin order: its clouds and tets.
    pub bins: Vec<BinPartsRef<'a>>,
}

/// One jaw bin's clouds and tets, borrowed.
#[derive(Debug, Clone)]
pub struct BinPartsRef<'a> {
    /// Every bundle's cloud (B).
    pub clouds: &'a [BundleCloud],
    /// Every bundle's tets (B).
    pub tets: Vec<&'a [Tet]>,
    /// The global fit's shape basis where derived ([`BinParts::fit_basis`]).
    pub fit_basis: Option<&'a Option<ShapeBasis>>,
}

/// Why parts did not make a model.
#[derive(Debug)]
pub enum PartsError {
    /// The parts contradict each other or their domains (for a file: it is corrupt or was
    /// written by something else); the message says which part.
    Inconsistent(String),
    /// Consistent parts whose assembly failed as a fresh build would.
    Build(LgiError),
}

impl Model {
    /// The model's parts, borrowed: everything [`Model::from_parts`] needs to rebuild it.
    pub fn parts(&self) -> ModelPartsRef<'_> {
        ModelPartsRef {
            dataset: &self.dataset,
            jaw: self.jaw.as_ref().map(|j| &j.input),
            config: &self.config,
            markers_rest: &self.markers_rest,
            bins: self
                .lookups
                .iter()
                .map(|lk| BinPartsRef {
                    clouds: &lk.clouds,
                    tets: lk.indices.iter().map(|i| i.tets()).collect(),
                    fit_basis: lk.basis.get(),
                })
                .collect(),
        }
    }

    /// A model from its parts (as [`Model::parts`] gives them), recomputing everything cheap
    /// (bundle correspondences, tet indices, sewing weights). The parts are checked first:
    /// the config's domains, the jaw against the dataset, one stored bin per jaw bin, and every
    /// cloud's shape ids against its bin's shapes.
    pub fn from_parts(parts: ModelParts) -> std::result::Result<Model, PartsError> {
        let bad = |e: LgiError| PartsError::Inconsistent(e.to_string());
        let ModelParts {
            dataset,
            jaw,
            config,
            markers_rest,
            bins,
        } = parts;
        config.validate().map_err(bad)?;
        let sources = lookup_sources(&dataset, jaw.as_ref()).map_err(bad)?;
        if sources.len() != bins.len() {
            return Err(PartsError::Inconsistent(
                "number of jaw bins does not match the stored clouds".into(),
            ));
        }
        let bundles =
            locate_bundles(dataset.neutral(), &markers_rest, &config).map_err(PartsError::Build)?;
        let mut lookups = Vec::with_capacity(sources.len());
        for (bin, (source, parts)) in sources.into_iter().zip(bins).enumerate() {
            let BinParts {
                clouds,
                tets,
                fit_basis,
            } = parts;
            let ns = source.num_shapes() as u32;
            if let Some(Some(basis)) = &fit_basis {
                if basis.shapes.iter().any(|&k| k >= source.num_shapes()) {
                    return Err(PartsError::Inconsistent(format!(
                        "bin {bin}: the fit's shape basis names a shape out of range"
                    )));
                }
            }
            if let Some(i) = clouds
                .iter()
                .position(|c| c.aliases.iter().flatten().any(|&s| s > ns))
            {
                return Err(PartsError::Inconsistent(format!(
                    "bin {bin}, bundle {i}: shape id out of range"
                )));
            }
            let shape_positions =
                lookup_bundle_positions(&dataset, &source, &bundles, jaw.as_ref())
                    .map_err(PartsError::Build)?;
            lookups.push(LookupParts {
                source,
                shape_positions,
                clouds,
                tets,
                fit_basis,
            });
        }
        Model::assemble(dataset, jaw, &markers_rest, &config, bundles, lookups)
            .map_err(PartsError::Build)
    }
}
