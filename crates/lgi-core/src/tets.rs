//! tets (to be implemented).
