//! Mesh readers and writers: OBJ (text) and glTF/GLB (gltf crate; morph targets are shapes).

pub mod glob;
pub mod gltf;
pub mod model_file;
pub mod obj;
