//! CPU ray backend.
