//! The frame loop.
