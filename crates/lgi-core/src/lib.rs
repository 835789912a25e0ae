//! lgi-core: Local Geometric Indexing (Cong, Lan & Fedkiw, IEEE TVCG 2023).
//!
//! Sparse facial markers ("bundles") index local geometry that really occurred in a dataset of
//! facial shapes; the pieces are sewn together with natural-neighbour weights so the surface
//! passes through every marker. Pure Rust: the Python binding lives in `lgi-python`.
//!
//! The public API is the list of re-exports below; the modules themselves are private, so a
//! type's home can move without breaking users (docs/architecture.md maps the modules).
// `deny`, not `forbid`: the one exception is the cache prefetch hint in `prefetch.rs`, kept
// because it measurably speeds up the choice (docs/journal/undated.md).
#![deny(unsafe_code)]
#![warn(missing_docs)]
// Every type reachable through the public API is in the list below.
#![warn(unnameable_types)]

mod augment;
mod baselines;
mod basis;
mod choose;
mod cloud;
mod correspond;
mod dataset;
mod error;
mod frame_blocks;
mod geodesic;
mod geom;
mod hash;
mod io;
mod jaw;
mod linalg;
mod local_fit;
mod magnitude;
mod mesh;
mod missing_rows;
mod model;
mod polygons;
mod prefetch;
mod prior;
mod ridge;
mod sew;
mod sibson;
mod simd;
mod smooth;
mod sparse;
mod take_prior;
#[cfg(test)]
mod test_values;
mod tet_index;
mod tets;
mod text;
mod uvspace;

// Data in and the model: what the binding and most users need.
pub use augment::{augment, recipes, Recipe};
pub use basis::ShapeBasis;
pub use dataset::Dataset;
pub use error::{LgiError, Result};
pub use local_fit::{
    blend_local, blend_local_frames, LocalFits, LocalWeights, SewingRows, LOCAL_LENGTH,
    WINDOW_REACH,
};
pub use magnitude::{
    check_dataset, Extent, Naming, MAGNITUDE_LIMIT, MAX_COORDINATE, MIN_PRESENT_MARKERS,
};
pub use mesh::{Mesh, SurfacePoint};
pub use missing_rows::{FillFit, MissingRows};
pub use model::{
    default_marker_names, BinParts, BinPartsRef, BuildConfig, BundleStats, FitResiduals, FrameInfo,
    FrameState, JawInput, JawPose, JawSetup, LocalShapeId, Lookup, Model, ModelParts,
    ModelPartsRef, PartsError, Sewn, ShapeId, SolveOptions, MAX_UNIT_LEN,
};
pub use polygons::Polygons;
pub use prior::{
    fit_scale, FitPrior, FrameFit, GramCache, FIELD_SIGNIFICANCE, FIELD_WINDOWS, FIT_L2,
    FIT_PENALTY, RESIDUAL_LENGTH,
};

// Files: meshes, datasets and the `.lgi` model file.
pub use io::glob::expand as expand_glob;
pub use io::gltf::read_gltf;
pub use io::model_file::{
    dataset_from_bytes, dataset_to_bytes, from_bytes as model_from_bytes, load as load_model,
    save as save_model, save_parts as save_model_parts, to_bytes as model_to_bytes,
};
pub use io::obj::{parse_obj, read_obj, read_obj_polygons, read_obj_positions, write_obj};

// The jaw (Eq. 2) and the baselines.
pub use baselines::{BlendshapeSolution, BlendshapeSolver, FitStart, RbfInterpolator};
pub use jaw::{validate_frame, JawBins, JawParams, JawRig, VertexMap, FRAME_TOLERANCE};
pub use ridge::RidgeFit;
pub use take_prior::{TakeFit, TakePrior};

// The stages of build and solve, public for the benches, for tests against brute force and
// for tools built on the core.
pub use choose::{
    alias_groups, AliasGroups, Choice, ChoiceParams, FrameErrors, Scoring, Scratch, NO_TET,
};
pub use cloud::{build_cloud, BundleCloud};
pub use correspond::{correspond, SurfaceIndex};
pub use geom::{closest_point_on_triangle, interpolate3};
pub use sew::{blend, blend_by_columns, BundleTargets, Pieces, SewPlan, ShapeSpans, BLEND_BLOCK};
pub use sibson::{Barrier, SibsonWeights};
pub use sparse::{BlockColumns, PatchBuffers, PatchedWeights, SparseWeights, WeightRows};
pub use tet_index::TetIndex;
pub use tets::{all_tets, closest_point_in_tet, generate_tets, tet_quality, Tet, TetConfig};
pub use uvspace::{boundary_barriers, vertex_charts, SewingSpace, UvIslands};

/// Re-exported so users of the core need not pin glam themselves.
pub use glam::{DVec2, DVec3};
