//! Every invariant of a built model's stored parts, in one check: run on the parts of a model
//! file before they are assembled (a file whose checksum was recomputed after editing is
//! refused here instead of panicking later) and by tests on freshly built models.

use super::{Model, ModelParts, ModelPartsRef};
use crate::magnitude::{Extent, MIN_PRESENT_MARKERS};
use crate::tets::Tet;

impl ModelParts {
    /// The parts, borrowed (what [`ModelPartsRef::sanity_check`] checks).
    pub fn as_parts_ref(&self) -> ModelPartsRef<'_> {
        ModelPartsRef {
            dataset: &self.dataset,
            jaw: self.jaw.as_ref(),
            config: &self.config,
            markers_rest: &self.markers_rest,
            bins: self
                .bins
                .iter()
                .map(|b| super::BinPartsRef {
                    clouds: &b.clouds,
                    tets: b.tets.iter().map(|t| t.as_slice()).collect(),
                    fit_basis: b.fit_basis.as_ref(),
                })
                .collect(),
        }
    }
}

impl Model {
    /// The model's parts, owned (for [`Model::from_parts`], or to edit into a crafted file).
    pub fn to_parts(&self) -> ModelParts {
        let p = self.parts();
        ModelParts {
            dataset: self.dataset_shared(),
            jaw: p.jaw.cloned(),
            config: p.config.clone(),
            markers_rest: p.markers_rest.to_vec(),
            bins: p
                .bins
                .iter()
                .map(|b| super::BinParts {
                    clouds: b.clouds.to_vec(),
                    tets: b.tets.iter().map(|t| t.to_vec()).collect(),
                    fit_basis: b.fit_basis.cloned(),
                })
                .collect(),
        }
    }

    /// Checks every invariant of the model's stored parts ([`ModelPartsRef::sanity_check`]):
    /// always `Ok` for a model that was built or loaded.
    pub fn sanity_check(&self) -> Result<(), String> {
        self.parts().sanity_check()
    }
}

impl ModelPartsRef<'_> {
    /// Checks what a build guarantees of its parts (the dataset checks itself on creation):
    /// a valid config; at least [`MIN_PRESENT_MARKERS`] finite markers within the magnitude
    /// limit of the neutral; a jaw consistent with the dataset (one weight per vertex, one
    /// valid pose per shape); one stored bin per jaw bin; per bin one cloud and one tet list
    /// per marker; every cloud non-empty, finite, within the limit, its point 0 the neutral,
    /// every shape id of its bin in exactly one alias list; every tet four distinct points of
    /// its cloud, at most `max_tets` per bundle. The message names bin, bundle and element.
    pub fn sanity_check(&self) -> Result<(), String> {
        self.config.validate().map_err(|e| e.to_string())?;
        let neutral = self.dataset.neutral();
        let extent = Extent::new(&neutral.positions, neutral.diagonal());
        let b = self.markers_rest.len();
        if b < MIN_PRESENT_MARKERS {
            return Err(format!(
                "{b} markers: a model has at least {MIN_PRESENT_MARKERS}"
            ));
        }
        for (i, m) in self.markers_rest.iter().enumerate() {
            if !m.is_finite() {
                return Err(format!(
                    "marker {i} is not finite: {}",
                    crate::text::point(*m)
                ));
            }
            extent
                .check_point(*m, &format!("marker {i}"))
                .map_err(|e| e.to_string())?;
        }
        let ns = self.dataset.num_shapes();
        let bin_shapes: Vec<usize> = match self.jaw {
            None => vec![ns],
            Some(j) => {
                if j.rig.num_vertices() != self.dataset.num_vertices() {
                    return Err(format!(
                        "jaw rig has {} weights for {} vertices",
                        j.rig.num_vertices(),
                        self.dataset.num_vertices()
                    ));
                }
                if j.shape_thetas.len() != ns {
                    return Err(format!(
                        "{} shape jaw poses for {ns} shapes",
                        j.shape_thetas.len()
                    ));
                }
                for (k, t) in j.shape_thetas.iter().enumerate() {
                    t.validate()
                        .and_then(|()| extent.check_jaw(t))
                        .map_err(|e| format!("shape {k}'s jaw pose: {e}"))?;
                }
                match &j.bins {
                    None => vec![ns],
                    Some(bins) => {
                        bins.validate().map_err(|e| e.to_string())?;
                        (0..bins.num_bins())
                            .map(|bin| bins.members(bin, &j.shape_thetas).len())
                            .collect()
                    }
                }
            }
        };
        if bin_shapes.len() != self.bins.len() {
            return Err(format!(
                "{} stored bins for {} jaw bins",
                self.bins.len(),
                bin_shapes.len()
            ));
        }
        for (bin, (parts, &shapes)) in self.bins.iter().zip(&bin_shapes).enumerate() {
            if parts.clouds.len() != b || parts.tets.len() != b {
                return Err(format!(
                    "bin {bin}: {} clouds and {} tet lists for {b} markers",
                    parts.clouds.len(),
                    parts.tets.len()
                ));
            }
            for (i, (cloud, tets)) in parts.clouds.iter().zip(&parts.tets).enumerate() {
                let at = |m: String| format!("bin {bin}, bundle {i}: {m}");
                check_cloud(cloud, shapes, &extent).map_err(at)?;
                check_tets(tets, cloud.points.len(), self.config.max_tets).map_err(at)?;
            }
        }
        Ok(())
    }
}

/// A cloud of a bin with `shapes` shapes (ids 0..=shapes, 0 the neutral).
fn check_cloud(
    cloud: &crate::cloud::BundleCloud,
    shapes: usize,
    extent: &Extent,
) -> Result<(), String> {
    if cloud.points.is_empty() {
        return Err("empty cloud (the neutral is always a point)".into());
    }
    if cloud.aliases.len() != cloud.points.len() {
        return Err(format!(
            "{} alias lists for {} points",
            cloud.aliases.len(),
            cloud.points.len()
        ));
    }
    for (p, x) in cloud.points.iter().enumerate() {
        if !x.is_finite() {
            return Err(format!("point {p} is not finite"));
        }
        extent
            .check_point(*x, &format!("point {p}"))
            .map_err(|e| e.to_string())?;
    }
    if cloud.aliases[0].first() != Some(&0) {
        return Err("point 0 is not the neutral (shape id 0)".into());
    }
    let mut seen = vec![false; shapes + 1];
    for (p, ids) in cloud.aliases.iter().enumerate() {
        if ids.is_empty() || !ids.windows(2).all(|w| w[0] < w[1]) {
            return Err(format!("point {p}: aliases empty or not ascending"));
        }
        for &s in ids {
            match seen.get_mut(s as usize) {
                None => {
                    return Err(format!(
                        "point {p}: shape id {s} out of range (0..={shapes})"
                    ))
                }
                Some(true) => return Err(format!("shape id {s} is an alias of two points")),
                Some(x) => *x = true,
            }
        }
    }
    if let Some(s) = seen.iter().position(|&x| !x) {
        return Err(format!("shape id {s} is in no alias list"));
    }
    Ok(())
}

/// Tets over a cloud of `points` points, at most `max_tets` of them.
fn check_tets(tets: &[Tet], points: usize, max_tets: usize) -> Result<(), String> {
    if tets.len() > max_tets {
        return Err(format!(
            "{} tets, more than max_tets {max_tets}",
            tets.len()
        ));
    }
    for (t, tet) in tets.iter().enumerate() {
        let distinct = (0..4).all(|a| (a + 1..4).all(|c| tet[a] != tet[c]));
        if !distinct || tet.iter().any(|&p| p as usize >= points) {
            return Err(format!(
                "tet {t} {tet:?} is not four distinct points of {points}"
            ));
        }
    }
    Ok(())
}
