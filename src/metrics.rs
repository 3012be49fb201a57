//! Image metrics (placeholder until the metrics module lands).
use std::path::Path;

#[derive(serde::Serialize)]
pub struct CompareReport {}

impl CompareReport {
    pub fn to_text(&self) -> String {
        String::new()
    }
}

pub fn compare_dirs(_reference: &Path, _test: &Path) -> anyhow::Result<CompareReport> {
    anyhow::bail!("not implemented")
}
