//! File formats: OBJ (text) and glTF/GLB (gltf crate; morph targets are shapes) meshes and
//! datasets, and the `.lgi` model file. `io` depends on the core types; they never read files.

pub mod atomic;
pub mod glob;
pub mod gltf;
pub mod model_file;
pub mod obj;

/// The message of a caught panic (`&str` or `String` payloads; the readers turn panics of
/// their dependencies into errors naming the file).
pub(crate) fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown reason".into())
}
