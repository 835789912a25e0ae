//! correspond (to be implemented).
