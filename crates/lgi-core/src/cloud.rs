//! cloud (to be implemented).
