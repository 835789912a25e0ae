//! sibson (to be implemented).
