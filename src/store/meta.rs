//! Reading `meta`'s integers: the big-endian values under the `META_*`
//! keys of [`super::keys`]. The store, the migration runner and the
//! migrations all read them here, so that a value of the wrong width is
//! refused in one way.

use super::keys;
use std::fmt;

/// Why a `meta` integer could not be read.
pub(crate) enum MetaError {
    Sled(sled::Error),
    /// The value holds `found` bytes, not the integer's `expected` width.
    Width {
        expected: usize,
        found: usize,
    },
}

impl fmt::Display for MetaError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            MetaError::Sled(e) => e.fmt(f),
            MetaError::Width { expected, found } => {
                write!(f, "expected {expected} bytes, found {found}")
            }
        }
    }
}

/// The `N` bytes under `key`, if there is a value.
fn read_bytes<const N: usize>(meta: &sled::Tree, key: &[u8]) -> Result<Option<[u8; N]>, MetaError> {
    let Some(v) = meta.get(key).map_err(MetaError::Sled)? else {
        return Ok(None);
    };
    let bytes = v.as_ref().try_into().map_err(|_| MetaError::Width {
        expected: N,
        found: v.len(),
    })?;
    Ok(Some(bytes))
}

/// The u32 under `key` (the schema version), if there is one.
pub(crate) fn read_meta_u32(meta: &sled::Tree, key: &[u8]) -> Result<Option<u32>, MetaError> {
    Ok(read_bytes(meta, key)?.map(u32::from_be_bytes))
}

/// The u64 under `key` (the sample log's length and generation, a
/// migration's progress), if there is one; the error names the key.
pub(crate) fn read_meta_u64(meta: &sled::Tree, key: &[u8]) -> Result<Option<u64>, String> {
    let named = |e: MetaError| match e {
        MetaError::Sled(e) => e.to_string(),
        MetaError::Width { .. } => format!("tree `meta` key {}: {e}", keys::describe(key)),
    };
    Ok(read_bytes(meta, key)
        .map_err(named)?
        .map(u64::from_be_bytes))
}
