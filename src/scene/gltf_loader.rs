//! glTF 2.0 loader (placeholder until the loader lands).
use super::{Scene, SceneError};
use std::path::Path;

pub fn load(path: &Path) -> Result<Scene, SceneError> {
    Err(SceneError::invalid(
        path.display().to_string(),
        "glTF loading is not implemented yet",
    ))
}
