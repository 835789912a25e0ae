//! Jaw-bin lookups: per bin (one when unbinned) the dataset re-posed to the bin's reference
//! pose, its bundle positions, clouds, alias groups and tet indices, and the map between the
//! bin's local shape ids and the dataset's.
//!
//! # Shape ids
//!
//! Three id spaces name a shape, all plain `u32`s in [`Choice::shapes`] and the clouds:
//!
//! - **bin-local** ([`LocalShapeId`]): inside one [`Lookup`], 0 is the bin's neutral and `j ≥ 1`
//!   the member shape `members[j - 1]`. Clouds, alias groups, tets and the choices of a solve
//!   (before they are reported) use these; smoothing and sewing work on them too, since the
//!   pieces are blended from the bin's own re-posed dataset.
//! - **dataset** ([`ShapeId`], the core's public id): 0 is the neutral, `k ≥ 1` dataset shape
//!   `k − 1`. [`Frame::choices`](super::Frame::choices) and
//!   [`FrameState::choices`](super::FrameState::choices) are in these. For an unbinned model
//!   the two spaces coincide (every shape is a member, in order).
//! - **Python**: -1 is the neutral, `k ≥ 0` dataset shape k (the binding subtracts 1 when it
//!   writes `choices.shapes`); it never reaches the core as an id. The core's 0-based dataset
//!   shape *indices* (`Dataset::displacement(k, _)`, [`Lookup::members`], the shapes' jaw poses)
//!   are the same numbers for the shapes, and have no neutral.
//!
//! [`Lookup::global_id`] and [`Lookup::local_id`] (and `localize`, which maps whole choices
//! with the latter) are the only crossings between the first two.

use crate::basis::ShapeBasis;
use crate::choose::{alias_groups, AliasGroups, Choice};
use crate::cloud::BundleCloud;
use crate::dataset::Dataset;
use crate::error::{LgiError, Result};
use crate::jaw::{JawParams, JawRig};
use crate::magnitude::Extent;
use crate::mesh::Mesh;
use crate::prior::FitPrior;
use crate::sew::{ShapeSpans, BLEND_BLOCK};
use crate::tet_index::TetIndex;
use crate::tets::Tet;
use glam::DVec3;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::Arc;
use std::sync::OnceLock;

use super::JawInput;

/// A shape id inside one jaw bin's [`Lookup`]: 0 the bin's neutral, `j ≥ 1` the member shape
/// `members[j - 1]` (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct LocalShapeId(pub u32);

/// A dataset shape id of the core: 0 the neutral, `k ≥ 1` dataset shape `k − 1` (see the
/// module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ShapeId(pub u32);

impl ShapeId {
    /// The neutral.
    pub const NEUTRAL: ShapeId = ShapeId(0);
}

/// The per-shape lookup structures of one jaw bin (the only one when unbinned): its shapes
/// re-posed to the bin's reference pose, their bundle positions, clouds, alias groups and
/// tet indices. Shape ids inside are local: 0 the bin's neutral, `j ≥ 1` the dataset shape
/// `members[j - 1]`.
#[derive(Debug)]
pub struct Lookup {
    /// The bin's reference pose; `None` for an unbinned model (shapes at the rest pose, and
    /// no re-posing of frames beyond the jaw unskinning).
    pub(super) reference: Option<JawParams>,
    pub(super) members: Vec<u32>,
    /// Dataset shape id (0 = neutral) → local id, `u32::MAX` for a non-member.
    pub(super) local_of: Vec<u32>,
    /// Neutral (skinned to the reference) and member displacements the pieces come from.
    pub(super) data: Arc<Dataset>,
    pub(super) shape_positions: Vec<DVec3>,
    pub(super) clouds: Vec<BundleCloud>,
    pub(super) groups: Vec<Vec<AliasGroups>>,
    pub(super) indices: Vec<TetIndex>,
    /// The global fit of this bin's shapes at the bundles (`None` without shapes): derived
    /// from `shape_positions`, not saved.
    pub(super) prior: Option<FitPrior>,
    /// The basis the fit is sewn over (derived on first use, see [`Lookup::fit_basis`]).
    pub(super) basis: OnceLock<Option<ShapeBasis>>,
    /// Where each of `data`'s shapes moves per blend block (derived on first use, see
    /// [`Lookup::shape_spans`]).
    pub(super) spans: OnceLock<ShapeSpans>,
}

impl Lookup {
    /// The basis of the bin's shapes that the global fit is sewn over ([`ShapeBasis`]):
    /// looked for on first use, and only when the fit's matrix has low rank (an augmented
    /// dataset, whose in-betweens and sums are combinations of its shapes); `None` otherwise.
    pub(super) fn fit_basis(&self) -> Option<&ShapeBasis> {
        self.basis
            .get_or_init(|| {
                let low = self.prior.as_ref().is_some_and(|p| p.low_rank().is_some());
                low.then(|| ShapeBasis::find(self.data.displacements(), self.data.num_shapes()))
                    .flatten()
            })
            .as_ref()
    }

    /// Where each of the bin's shapes moves, per block of the blend: what the global fit's
    /// sewing reads ([`ShapeSpans`]); found on first use (one pass over the shapes).
    pub(super) fn shape_spans(&self) -> &ShapeSpans {
        self.spans.get_or_init(|| {
            ShapeSpans::new(
                self.data.displacements(),
                self.data.num_vertices(),
                BLEND_BLOCK,
            )
        })
    }

    /// The bin's reference pose (`None` when the model is unbinned).
    pub fn reference(&self) -> Option<JawParams> {
        self.reference
    }
    /// Dataset shape index (0-based) of each local shape id `j ≥ 1` (`members[j - 1]`).
    pub fn members(&self) -> &[u32] {
        &self.members
    }
    /// Clouds of all bundles (local shape ids).
    pub fn clouds(&self) -> &[BundleCloud] {
        &self.clouds
    }
    /// Alias groups of every bundle's cloud points.
    pub fn alias_groups(&self) -> &[Vec<AliasGroups>] {
        &self.groups
    }
    /// Tet indices of all bundles.
    pub fn indices(&self) -> &[TetIndex] {
        &self.indices
    }
    /// Bundle positions on every local shape, `(members + 1) × B`.
    pub fn shape_positions(&self) -> &[DVec3] {
        &self.shape_positions
    }
    /// The dataset shape id of a local shape id.
    ///
    /// # Panics
    /// If `local` is not one of the bin's ids (`0..=members.len()`).
    pub fn global_id(&self, local: LocalShapeId) -> ShapeId {
        match local.0 {
            0 => ShapeId::NEUTRAL,
            j => ShapeId(self.members[j as usize - 1] + 1),
        }
    }
    /// The bin-local id of a dataset shape id; `None` when the shape is not a member.
    pub fn local_id(&self, global: ShapeId) -> Option<LocalShapeId> {
        match self.local_of.get(global.0 as usize) {
            Some(&j) if j != u32::MAX => Some(LocalShapeId(j)),
            _ => None,
        }
    }
    /// A choice with its shape ids mapped from local to dataset ids.
    pub(super) fn globalize(&self, mut c: Choice) -> Choice {
        for s in &mut c.shapes {
            *s = self.global_id(LocalShapeId(*s)).0;
        }
        c
    }
    /// Choices in dataset ids ([`ShapeId`]) mapped to this bin's local ids ([`LocalShapeId`];
    /// a non-member shape gets `u32::MAX`, an id no candidate has); borrowed unchanged for an
    /// unbinned model.
    pub(super) fn localize<'a>(&self, choices: &'a [Option<Choice>]) -> Cow<'a, [Option<Choice>]> {
        if self.reference.is_none() {
            return Cow::Borrowed(choices);
        }
        let map = |s: u32| self.local_id(ShapeId(s)).map_or(u32::MAX, |l| l.0);
        Cow::Owned(
            choices
                .iter()
                .map(|c| {
                    c.map(|mut c| {
                        for s in &mut c.shapes {
                            *s = map(*s);
                        }
                        c
                    })
                })
                .collect(),
        )
    }
}

/// What one lookup is built from: its reference pose, member shapes and re-posed dataset.
pub(super) struct LookupSource {
    reference: Option<JawParams>,
    members: Vec<u32>,
    data: Arc<Dataset>,
}

impl LookupSource {
    /// Number of local shapes (members, not counting the neutral).
    pub(super) fn num_shapes(&self) -> usize {
        self.members.len()
    }
    /// The re-posed dataset (bin neutral and member displacements).
    pub(super) fn data(&self) -> &Dataset {
        &self.data
    }
    /// Dataset shape index (0-based) of each member.
    pub(super) fn members(&self) -> &[u32] {
        &self.members
    }
    /// The bin's reference pose (`None` unbinned).
    pub(super) fn reference(&self) -> Option<JawParams> {
        self.reference
    }
}

/// A lookup's source with its built clouds and tets (what a saved model stores).
pub(super) struct LookupParts {
    pub(super) source: LookupSource,
    pub(super) shape_positions: Vec<DVec3>,
    pub(super) clouds: Vec<BundleCloud>,
    pub(super) tets: Vec<Vec<Tet>>,
    /// The fit's shape basis where already derived ([`super::BinParts::fit_basis`]).
    pub(super) fit_basis: Option<Option<ShapeBasis>>,
}

impl Lookup {
    /// The lookup of built `part`: its tet indices and alias groups (with the bundles' natural
    /// `neighbours`, `num_bundles` B) and the local ids of a dataset of `num_shapes` shapes.
    pub(super) fn new(
        part: LookupParts,
        neighbours: &[Vec<u32>],
        num_shapes: usize,
        num_bundles: usize,
    ) -> Result<Lookup> {
        let b = num_bundles;
        let indices: Vec<TetIndex> = part
            .clouds
            .par_iter()
            .zip(part.tets)
            .map(|(c, t)| TetIndex::new(c.points.clone(), t))
            .collect::<Result<_>>()?;
        let groups = part
            .clouds
            .par_iter()
            .zip(neighbours)
            .map(|(c, nb)| alias_groups(c, nb, &part.shape_positions, b))
            .collect();
        let src = part.source;
        let mut local_of = vec![u32::MAX; num_shapes + 1];
        local_of[0] = 0;
        for (j, &k) in src.members.iter().enumerate() {
            local_of[k as usize + 1] = j as u32 + 1;
        }
        let prior = FitPrior::new(&part.shape_positions, b)?;
        Ok(Lookup {
            prior,
            basis: match part.fit_basis {
                Some(derived) => OnceLock::from(derived),
                None => OnceLock::new(),
            },
            spans: OnceLock::new(),
            reference: src.reference,
            members: src.members,
            local_of,
            data: src.data,
            shape_positions: part.shape_positions,
            clouds: part.clouds,
            groups,
            indices,
        })
    }
}

/// The dataset whose pieces are indexed when unbinned: with a jaw, every shape's jaw motion is
/// unskinned, `s*_k = T(θ_k)⁻¹ (x0 + s_k) − x0` (Eq. 2), so clouds hold expression without jaw
/// rotation.
fn unskinned_dataset(
    dataset: &Arc<Dataset>,
    rig: &JawRig,
    thetas: &[JawParams],
) -> Result<Arc<Dataset>> {
    let mesh = dataset.neutral();
    let disp = rig.unskin_shapes(&mesh.positions, dataset.displacements(), thetas)?;
    Ok(Arc::new(Dataset::new(
        mesh.clone(),
        disp,
        dataset.names().to_vec(),
    )?))
}

/// What each lookup is built from: without a jaw the dataset as given; with a jaw and no bins
/// every shape unskinned to the rest pose; with bins, per bin its member shapes re-posed to the
/// bin's reference, `T(θ_b) T(θ_k)⁻¹ (x0 + s_k)`, relative to the bin's neutral `T(θ_b) x0`.
pub(super) fn lookup_sources(
    dataset: &Arc<Dataset>,
    jaw: Option<&JawInput>,
) -> Result<Vec<LookupSource>> {
    let all = || (0..dataset.num_shapes() as u32).collect();
    let Some(j) = jaw else {
        return Ok(vec![LookupSource {
            reference: None,
            members: all(),
            data: dataset.clone(),
        }]);
    };
    let (rig, thetas) = (&j.rig, &j.shape_thetas);
    if rig.num_vertices() != dataset.num_vertices() {
        return Err(LgiError::Input(format!(
            "jaw rig has {} weights, the dataset {} vertices",
            rig.num_vertices(),
            dataset.num_vertices()
        )));
    }
    if thetas.len() != dataset.num_shapes() {
        return Err(LgiError::Input(format!(
            "{} shape jaw poses for {} shapes",
            thetas.len(),
            dataset.num_shapes()
        )));
    }
    let extent = Extent::new(&dataset.neutral().positions, dataset.neutral().diagonal());
    extent.check_point(rig.pivot, "jaw pivot")?;
    for (k, t) in thetas.iter().enumerate() {
        t.validate()
            .and_then(|()| extent.check_jaw(t))
            .map_err(|e| LgiError::Input(format!("shape {k}'s jaw pose: {e}")))?;
    }
    let Some(bins) = &j.bins else {
        return Ok(vec![LookupSource {
            reference: None,
            members: all(),
            data: unskinned_dataset(dataset, rig, thetas)?,
        }]);
    };
    bins.validate()?;
    let mesh = dataset.neutral();
    (0..bins.num_bins())
        .map(|b| {
            let members = bins.members(b, thetas);
            if members.is_empty() {
                let (lo, hi) = bins.core_range(b);
                return Err(LgiError::Input(format!(
                    "jaw bin {b} (opening {lo} to {hi} rad, overlap {}) has no member shapes: \
                     no dataset shape opens the jaw that far; change the bin edges",
                    bins.overlap
                )));
            }
            let reference = bins.reference(b);
            let (base, disp) = rig.repose_shapes(
                &mesh.positions,
                dataset.displacements(),
                thetas,
                &members,
                reference,
            )?;
            let names = members
                .iter()
                .map(|&k| dataset.names()[k as usize].clone())
                .collect();
            let neutral = Mesh {
                positions: base,
                ..mesh.clone()
            };
            Ok(LookupSource {
                reference: Some(reference),
                members,
                data: Arc::new(Dataset::new(neutral, disp, names)?),
            })
        })
        .collect()
}
