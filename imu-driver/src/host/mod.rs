//! Host side (std).
