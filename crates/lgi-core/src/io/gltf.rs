//! glTF reader (to be implemented).
