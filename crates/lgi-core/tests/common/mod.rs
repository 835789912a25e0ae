//! Helpers shared by the integration tests.

use std::path::{Path, PathBuf};

/// The ICT-FaceKit data: `$LGI_SHARED_DATA/ict-facekit` (as for the Python tests), else
/// `shared/data/ict-facekit` in the nearest ancestor of this crate that has it (the checkout's
/// sibling `shared/`). `None` (the caller skips, saying why) when absent.
pub fn ict_dir() -> Option<PathBuf> {
    let from_env =
        std::env::var_os("LGI_SHARED_DATA").map(|d| PathBuf::from(d).join("ict-facekit"));
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    from_env
        .into_iter()
        .chain(
            manifest
                .ancestors()
                .map(|a| a.join("shared/data/ict-facekit")),
        )
        .find(|d| {
            d.join("generic_neutral_mesh.obj").is_file() && d.join("markers_120.csv").is_file()
        })
}
