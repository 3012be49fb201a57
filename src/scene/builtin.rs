//! Built-in scenes (placeholder until they land).
use super::{Scene, SceneError};

pub const NAMES: &[&str] = &["cube-in-box"];

pub fn build(name: &str) -> Result<Scene, SceneError> {
    Err(SceneError::UnknownBuiltin(name.to_string()))
}
