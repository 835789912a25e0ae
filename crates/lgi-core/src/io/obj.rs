//! OBJ reader/writer (to be implemented).
