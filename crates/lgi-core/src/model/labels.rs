//! A model's labels: each marker's name (a take is matched to the layout by label) and the
//! length unit of its coordinates (a take in other units is converted). Neither changes the
//! geometry; a model built without them has the names `m000`, `m001`, … and no unit.

use super::Model;
use crate::error::{LgiError, Result};

/// Longest accepted unit name (bytes): units are short words (`mm`, `cm`, `m`, `in`).
pub const MAX_UNIT_LEN: usize = 16;

/// The names of a layout given without names: `m000`, `m001`, … (at least three digits, so
/// they sort in marker order).
pub fn default_marker_names(count: usize) -> Vec<String> {
    (0..count).map(|i| format!("m{i:03}")).collect()
}

/// Marker names (one per bundle, unique) and the unit (empty: unknown).
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Labels {
    pub(crate) marker_names: Vec<String>,
    pub(crate) units: String,
}

impl Labels {
    pub(crate) fn unnamed(count: usize) -> Labels {
        Labels {
            marker_names: default_marker_names(count),
            units: String::new(),
        }
    }
}

/// Checks `names` label `count` markers: one each, non-empty, printable without surrounding
/// spaces (they are matched to a take's labels as written), unique.
fn check_names(names: &[String], count: usize) -> Result<()> {
    if names.len() != count {
        return Err(LgiError::Input(format!(
            "marker_names: {} names for {count} markers",
            names.len()
        )));
    }
    let mut seen = std::collections::HashMap::new();
    for (i, n) in names.iter().enumerate() {
        if n.is_empty() || n.trim() != n || n.chars().any(char::is_control) {
            return Err(LgiError::Input(format!(
                "marker_names: marker {i}: name {n:?} is empty, has surrounding spaces or \
                 control characters"
            )));
        }
        if let Some(j) = seen.insert(n.as_str(), i) {
            return Err(LgiError::Input(format!(
                "marker_names: markers {j} and {i} are both named {n:?}"
            )));
        }
    }
    Ok(())
}

fn check_units(units: &str) -> Result<()> {
    if units.len() > MAX_UNIT_LEN || !units.chars().all(|c| c.is_ascii_alphanumeric()) {
        return Err(LgiError::Input(format!(
            "units: {units:?} is not a unit name (a short word such as 'cm' or 'mm')"
        )));
    }
    Ok(())
}

impl Model {
    /// The same model with its markers named `names` (B, unique) and its coordinates in
    /// `units` (a short name such as `cm`; empty: unknown). Interpreting units is the caller's
    /// job (the Python package converts takes); the model only keeps them.
    pub fn with_labels(mut self, names: Vec<String>, units: String) -> Result<Model> {
        check_names(&names, self.markers_rest.len())?;
        check_units(&units)?;
        self.labels = Labels {
            marker_names: names,
            units,
        };
        Ok(self)
    }

    /// Each marker's name (B); `m000`, `m001`, … for a model built without names.
    pub fn marker_names(&self) -> &[String] {
        &self.labels.marker_names
    }

    /// The length unit of the model's coordinates; empty when not given.
    pub fn units(&self) -> &str {
        &self.labels.units
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_names_are_numbered_in_marker_order() {
        assert_eq!(default_marker_names(3), ["m000", "m001", "m002"]);
        let many = default_marker_names(1001);
        assert_eq!(many[1000], "m1000");
        let mut sorted = many[..1000].to_vec();
        sorted.sort();
        assert_eq!(sorted, many[..1000]);
    }

    #[test]
    fn names_must_be_one_per_marker_unique_and_clean() {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        check_names(&s(&["a", "b"]), 2).unwrap();
        assert!(check_names(&s(&["a"]), 2).is_err());
        let e = check_names(&s(&["a", "b", "a"]), 3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("markers 0 and 2"), "{e}");
        assert!(check_names(&s(&["a", " b"]), 2).is_err());
        assert!(check_names(&s(&["a", ""]), 2).is_err());
        check_units("cm").unwrap();
        check_units("").unwrap();
        assert!(check_units("c m").is_err());
    }
}
