//! Baselines that LGI is evaluated against: smooth interpolation of marker displacements
//! (`rbf`) and a global least-squares blendshape fit (`blendshape`). They share nothing with the
//! LGI solve, so a comparison measures the method and not shared code.

pub mod blendshape;
pub mod rbf;

pub use blendshape::{BlendshapeSolution, BlendshapeSolver};
pub use rbf::DisplacementInterpolation;
