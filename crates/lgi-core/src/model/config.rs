//! Build parameters of a [`Model`](super::Model) and their domains: one place for the defaults
//! (measured on the real data) and the checks a build and a loaded file both run.

use crate::error::{LgiError, Result};

/// Build parameters. Distances are relative to the neutral's bounding-box diagonal.
#[derive(Debug, Clone, PartialEq)]
pub struct BuildConfig {
    /// Markers farther than this from the neutral surface are an error (relative).
    pub surface_tolerance: f64,
    /// Shapes moving a bundle less than this are aliases of the neutral point (relative).
    pub prune_motion: f64,
    /// Cloud points closer than this are merged as aliases (relative).
    pub duplicate_distance: f64,
    /// Nearest neighbours per cloud point for tet generation.
    pub tet_neighbours: usize,
    /// Tets kept per bundle, best quality first.
    pub max_tets: usize,
    /// Tets below this quality (1 = regular) are dropped.
    pub min_quality: f64,
    /// Tets with an edge longer than this are dropped (relative; infinity = no limit).
    pub max_edge: f64,
    /// Barycentric tolerance of "contains".
    pub containment_eps: f64,
    /// Nearest tets scored when a target is outside every tet.
    pub projection_candidates: usize,
    /// Penalty per shape not shared with the previous frame's choice (relative to diagonal²).
    pub temporal_weight: f64,
    /// A bundle gives no weight to a vertex (and is no neighbour of another bundle) when the
    /// surface path between them is longer than this many times the straight line: that path
    /// goes around a hole (the mouth slit, an eye). Infinity disables the rule.
    pub detour_ratio: f64,
}

impl Default for BuildConfig {
    fn default() -> Self {
        BuildConfig {
            surface_tolerance: 0.02,
            prune_motion: 1e-5,
            duplicate_distance: 1e-7,
            tet_neighbours: 10,
            max_tets: 20_000,
            min_quality: 0.02,
            max_edge: f64::INFINITY,
            containment_eps: 1e-9,
            projection_candidates: 8,
            temporal_weight: 1e-6,
            detour_ratio: 1.4,
        }
    }
}

impl BuildConfig {
    /// Checks every field's domain.
    pub fn validate(&self) -> Result<()> {
        let pos = |name: &str, v: f64| {
            if v.is_nan() || v <= 0.0 {
                Err(LgiError::Input(format!(
                    "BuildConfig.{name} must be > 0, got {v}"
                )))
            } else {
                Ok(())
            }
        };
        pos("surface_tolerance", self.surface_tolerance)?;
        pos("max_edge", self.max_edge)?;
        if self.detour_ratio.is_nan() || self.detour_ratio < 1.0 {
            return Err(LgiError::Input(format!(
                "BuildConfig.detour_ratio must be >= 1, got {}",
                self.detour_ratio
            )));
        }
        for (name, v) in [
            ("prune_motion", self.prune_motion),
            ("duplicate_distance", self.duplicate_distance),
            ("containment_eps", self.containment_eps),
            ("temporal_weight", self.temporal_weight),
            ("min_quality", self.min_quality),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(LgiError::Input(format!(
                    "BuildConfig.{name} must be finite and >= 0, got {v}"
                )));
            }
        }
        if self.tet_neighbours < 3 || self.max_tets == 0 || self.projection_candidates == 0 {
            return Err(LgiError::Input(
                "BuildConfig.tet_neighbours must be >= 3, max_tets and projection_candidates >= 1"
                    .into(),
            ));
        }
        Ok(())
    }
}
