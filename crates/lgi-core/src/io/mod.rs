//! File formats: OBJ (text) and glTF/GLB (gltf crate; morph targets are shapes) meshes and
//! datasets, and the `.lgi` model file. `io` depends on the core types; they never read files.

pub mod gltf;
pub mod model_file;
pub mod obj;
