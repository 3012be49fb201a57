//! BSDFs.
