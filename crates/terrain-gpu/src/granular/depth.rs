//! Depth of objects seen from below on the GPU (being written).
