//! The one bound on magnitudes: finite but absurd numbers (a marker at 1e30, a shape that moves
//! a vertex by 1e30, a jaw pushed forward by 1e200) give infinities or silently exploded meshes
//! downstream, so everything the user gives is checked against a multiple of the face's size
//! (the neutral's bounding-box diagonal) at the entry points, by the functions here only.

use crate::error::{LgiError, Result};
use crate::jaw::JawParams;
use crate::text::{length, num, point_in};
use glam::DVec3;

/// How far (in neutral diagonals) a marker may lie from the centre of the rest layout, a shape
/// may move a vertex, or a jaw may translate. A marker 100 face sizes away cannot be on the
/// face: it is a unit mistake (metres vs millimetres is 1000×) or a tracking error.
pub const MAGNITUDE_LIMIT: f64 = 100.0;

/// The largest absolute neutral coordinate: beyond it, squared distances of the face's own
/// size (the unit of every tolerance) are no longer far from overflowing.
pub const MAX_COORDINATE: f64 = 1e30;

/// Fewest markers a frame must have present, for every method (sewing needs a triangle).
pub const MIN_PRESENT_MARKERS: usize = 3;

/// `x <= limit`, false for NaN (so a NaN magnitude is never accepted).
fn within(x: f64, limit: f64) -> bool {
    x.partial_cmp(&limit).is_some_and(|o| o.is_le())
}

/// How messages name a frame's markers and lengths: the markers' labels (by index; none: by
/// index alone) and the unit of the coordinates (empty: unknown).
#[derive(Debug, Clone, Copy, Default)]
pub struct Naming<'a> {
    /// One label per marker, or empty.
    pub names: &'a [String],
    /// The coordinates' unit (`cm`), or empty.
    pub units: &'a str,
}

impl Naming<'_> {
    /// `marker m005 (5)`, or `marker 5` without labels.
    pub fn marker(&self, i: usize) -> String {
        match self.names.get(i) {
            Some(n) => format!("marker {n} ({i})"),
            None => format!("marker {i}"),
        }
    }
}

/// Where the face is and how large: the reference of every magnitude check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Extent {
    /// Centre of the bounding box of the markers' rest positions.
    pub centre: DVec3,
    /// The neutral's bounding-box diagonal.
    pub diagonal: f64,
}

impl Extent {
    /// The extent of a point set (the marker rest layout, or the neutral itself) on a
    /// neutral of diagonal `diagonal`.
    pub fn new(points: &[DVec3], diagonal: f64) -> Extent {
        let (lo, hi) = points
            .iter()
            .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(*p), hi.max(*p))
            });
        let centre = if points.is_empty() {
            DVec3::ZERO
        } else {
            (lo + hi) * 0.5
        };
        Extent { centre, diagonal }
    }

    /// The largest distance from [`centre`](Self::centre) a marker may have.
    pub fn limit(&self) -> f64 {
        MAGNITUDE_LIMIT * self.diagonal
    }

    /// Checks one frame of marker positions (B): a NaN row is a missing marker; a row with an
    /// infinite coordinate, or farther than [`limit`](Self::limit) from the centre, is an
    /// error naming the marker; fewer than [`MIN_PRESENT_MARKERS`] present is an error.
    pub fn check_frame(&self, targets: &[DVec3], naming: Naming<'_>) -> Result<()> {
        let mut present = 0;
        for (i, t) in targets.iter().enumerate() {
            if t.to_array().iter().any(|x| x.is_infinite()) {
                return Err(LgiError::Input(format!(
                    "{} has an infinite coordinate {}",
                    naming.marker(i),
                    point_in(*t, naming.units)
                )));
            }
            if t.is_nan() {
                continue;
            }
            present += 1;
            self.check_point_in(*t, &naming.marker(i), naming.units)?;
        }
        if present < MIN_PRESENT_MARKERS {
            return Err(LgiError::Input(format!(
                "only {present} markers present: at least {MIN_PRESENT_MARKERS} are needed"
            )));
        }
        Ok(())
    }

    /// Checks that point `p` (named `what` in the error) lies within [`limit`](Self::limit)
    /// of the centre.
    pub fn check_point(&self, p: DVec3, what: &str) -> Result<()> {
        self.check_point_in(p, what, "")
    }

    /// [`check_point`](Self::check_point) with the coordinates' unit for the message.
    pub fn check_point_in(&self, p: DVec3, what: &str, units: &str) -> Result<()> {
        let d = p.distance(self.centre);
        if !within(d, self.limit()) {
            return Err(LgiError::Input(format!(
                "{what} at {} is {} from the face's centre, beyond {MAGNITUDE_LIMIT} x the \
                 face's size ({} x {MAGNITUDE_LIMIT} = {}): wrong unit or a tracking error",
                point_in(p, units),
                if d.is_finite() {
                    length(d, units)
                } else {
                    format!("more than {}", length(f64::MAX, units))
                },
                length(self.diagonal, units),
                length(self.limit(), units),
            )));
        }
        Ok(())
    }

    /// [`check_frame`](Self::check_frame) for every frame, the error naming the frame.
    pub fn check_frames(&self, frames: &[Vec<DVec3>], naming: Naming<'_>) -> Result<()> {
        for (f, t) in frames.iter().enumerate() {
            self.check_frame(t, naming).map_err(|e| match e {
                LgiError::Input(m) => LgiError::Input(format!("frame {f}: {m}")),
                other => other,
            })?;
        }
        Ok(())
    }

    /// Checks a marker noise (a distance, `None`: exact) against [`limit`](Self::limit).
    pub fn check_marker_noise(&self, sigma: Option<f64>) -> Result<()> {
        match sigma {
            Some(s) if !within(s.abs(), self.limit()) => Err(LgiError::Input(format!(
                "marker_noise {} is beyond {MAGNITUDE_LIMIT} x the face's size ({})",
                num(s),
                num(self.limit())
            ))),
            _ => Ok(()),
        }
    }

    /// Checks a jaw pose's translation against [`limit`](Self::limit) (its angles are
    /// bounded by [`JawParams::validate`]).
    pub fn check_jaw(&self, theta: &JawParams) -> Result<()> {
        if !within(theta.forward.abs(), self.limit()) {
            return Err(LgiError::Input(format!(
                "jaw forward translation {} is beyond {MAGNITUDE_LIMIT} x the face's size ({})",
                num(theta.forward),
                num(self.limit())
            )));
        }
        Ok(())
    }
}

/// Checks a dataset's neutral coordinates against [`MAX_COORDINATE`] and its displacements
/// (S × V × 3) against [`MAGNITUDE_LIMIT`] × `diagonal`, naming shape and vertex.
pub fn check_dataset(
    positions: &[DVec3],
    displacements: &[f32],
    names: &[String],
    diagonal: f64,
) -> Result<()> {
    if let Some(v) = positions
        .iter()
        .position(|p| !within(p.abs().max_element(), MAX_COORDINATE))
    {
        return Err(LgiError::Dataset(format!(
            "neutral vertex {v} at {} is beyond {} in absolute value",
            crate::text::point(positions[v]),
            num(MAX_COORDINATE)
        )));
    }
    let limit = MAGNITUDE_LIMIT * diagonal;
    let nv = positions.len().max(1);
    for (i, d) in displacements.chunks_exact(3).enumerate() {
        let len = DVec3::new(d[0].into(), d[1].into(), d[2].into()).length();
        if !within(len, limit) {
            let k = i / nv;
            return Err(LgiError::Dataset(format!(
                "shape {k} ('{}'), vertex {}: displacement {} is beyond {MAGNITUDE_LIMIT} x \
                 the neutral's size ({})",
                names.get(k).map_or("?", |s| s.as_str()),
                i % nv,
                num(len),
                num(limit)
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Extent {
        // Markers on a unit square: centre (0.5, 0.5, 0); diagonal 2 given.
        let m = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.0)];
        Extent::new(&m, 2.0)
    }

    #[test]
    fn extent_centre_is_the_bounding_box_centre_of_the_layout() {
        assert_eq!(square().centre, DVec3::new(0.5, 0.5, 0.0));
        assert_eq!(square().limit(), 200.0);
    }

    #[test]
    fn marker_just_inside_the_limit_passes_and_just_outside_is_named() {
        let e = square();
        let c = e.centre;
        let mut t = vec![c, c, c, c + DVec3::X * 199.999];
        e.check_frame(&t, Naming::default()).unwrap();
        t[3] = c + DVec3::X * 200.001;
        let msg = e
            .check_frame(&t, Naming::default())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("marker 3"), "{msg}");
        // Labels and the unit reach the message; no Rust debug formatting does.
        let names: Vec<String> = ["a", "b", "c", "nose"].map(String::from).to_vec();
        let named = Naming {
            names: &names,
            units: "cm",
        };
        let msg = e.check_frame(&t, named).unwrap_err().to_string();
        assert!(
            msg.contains("marker nose (3) at (200.5, 0.5, 0) cm is 200 cm from"),
            "{msg}"
        );
        assert!(msg.contains("(2 cm x 100 = 200 cm)"), "{msg}");
        assert!(!msg.contains("DVec3") && !msg.contains("e2"), "{msg}");
        t[3] = DVec3::splat(1e200);
        let msg = e
            .check_frames(&[t.clone(), t], Naming::default())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("frame 0: marker 3"), "{msg}");
    }

    #[test]
    fn missing_markers_are_skipped_but_too_few_present_is_an_error() {
        let e = square();
        let c = e.centre;
        e.check_frame(&[c, c, c, DVec3::NAN], Naming::default())
            .unwrap();
        let msg = e
            .check_frame(&[c, DVec3::NAN, c, DVec3::NAN], Naming::default())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("only 2 markers present"), "{msg}");
        let nan = DVec3::NAN;
        assert!(e.check_frame(&[nan; 4], Naming::default()).is_err());
    }

    #[test]
    fn jaw_translation_beyond_the_limit_is_rejected() {
        let e = square();
        let mut t = JawParams::ZERO;
        t.forward = 199.0;
        e.check_jaw(&t).unwrap();
        t.forward = -1e200;
        assert!(e.check_jaw(&t).is_err());
    }

    #[test]
    fn dataset_displacement_beyond_the_limit_names_shape_and_vertex() {
        let p = [DVec3::ZERO, DVec3::X, DVec3::Y];
        let names = vec!["a".to_string(), "b".to_string()];
        let mut d = vec![0.0f32; 18];
        check_dataset(&p, &d, &names, 1.0).unwrap();
        d[3 * 3 + 3 + 1] = 1e30; // shape 1, vertex 1
        let msg = check_dataset(&p, &d, &names, 1.0).unwrap_err().to_string();
        assert!(msg.contains("shape 1 ('b'), vertex 1"), "{msg}");
        let far = [DVec3::ZERO, DVec3::X, DVec3::splat(1e200)];
        assert!(check_dataset(&far, &[], &[], 1.0).is_err());
    }
}
