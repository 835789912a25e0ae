//! Glob patterns of shape files (`shapes/*.obj`): the matches in sorted order, so a dataset
//! read from a pattern has the same shape order on every machine.

use std::path::PathBuf;

use crate::error::{LgiError, Result};

/// The files matching `pattern`, sorted (empty when nothing matches: whether that is an error
/// is the caller's call). A malformed pattern is an `Input` error; an unreadable directory on
/// the way an `Io` error naming it.
pub fn expand(pattern: &str) -> Result<Vec<PathBuf>> {
    let entries = ::glob::glob(pattern)
        .map_err(|e| LgiError::Input(format!("bad glob pattern '{pattern}': {e}")))?;
    let mut out = Vec::new();
    for entry in entries {
        out.push(entry.map_err(|e| LgiError::io(e.path(), e.error()))?);
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_come_sorted_and_no_match_is_empty() {
        let dir = std::env::temp_dir().join(format!("lgi-glob-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for name in ["b.obj", "a.obj", "c.txt"] {
            std::fs::write(dir.join(name), "").unwrap();
        }
        let pattern = format!("{}/*.obj", dir.display());
        let got = expand(&pattern).unwrap();
        assert_eq!(got, vec![dir.join("a.obj"), dir.join("b.obj")]);
        assert!(expand(&format!("{}/*.gltf", dir.display()))
            .unwrap()
            .is_empty());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_malformed_pattern_is_an_input_error() {
        let err = expand("shapes/[").unwrap_err();
        assert!(matches!(err, LgiError::Input(ref m) if m.contains("bad glob pattern")));
    }
}
