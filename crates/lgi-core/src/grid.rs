//! grid (to be implemented).
