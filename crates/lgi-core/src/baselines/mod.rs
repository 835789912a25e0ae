//! Numerical kernels of the baselines that LGI is evaluated against: a biharmonic RBF
//! interpolator (`rbf`; displacement interpolation, LGI-RBF's correction) and a global
//! least-squares blendshape fit (`blendshape`). They share nothing with the
//! LGI solve, so a comparison measures the method and not shared code.

pub mod blendshape;
pub mod rbf;

pub(crate) use blendshape::{check_target, PieceFactors};
pub use blendshape::{BlendshapeSolution, BlendshapeSolver, FitStart};
pub use rbf::RbfInterpolator;
