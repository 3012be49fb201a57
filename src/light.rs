//! Light sampling.
