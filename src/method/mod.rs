//! Rendering methods.
