//! lgi-core: Local Geometric Indexing (Cong, Lan & Fedkiw, IEEE TVCG 2023).
//!
//! Sparse facial markers ("bundles") index local geometry that really occurred in a dataset of
//! facial shapes; the pieces are sewn together with natural-neighbour weights so the surface
//! passes through every marker. Pure Rust: the Python binding lives in `lgi-python`.
// `deny`, not `forbid`: the one measured exception is the cache prefetch hint in `prefetch.rs`
// (serial choice 2.31 -> 1.99 ms per frame on ICT-300, docs/performance.md).
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod augment;
pub mod baselines;
pub mod choose;
pub mod cloud;
pub mod correspond;
pub mod dataset;
pub mod error;
pub mod geodesic;
pub mod geom;
pub mod grid;
pub mod io;
pub mod jaw;
pub mod linalg;
pub mod mesh;
pub mod model;
mod prefetch;
pub mod prior;
pub mod sew;
pub mod sibson;
pub mod smooth;
pub mod tets;
pub mod uvspace;

pub use dataset::Dataset;
pub use error::{LgiError, Result};
pub use mesh::Mesh;

/// Re-exported so users of the core need not pin glam themselves.
pub use glam::{DVec2, DVec3};
