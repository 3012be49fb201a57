//! What the methods that carry a cache from frame to frame (`trc`, `tcg`)
//! share of their carried state's bytes ([`super::StateChanges`]): the
//! method-wide part, the next record id, as an rkyv archive; and reading
//! the records back in id order. Each method encodes its records itself.
//! The layouts are part of the store schema (`migrations/`).

use super::{MethodState, StateError};
use crate::cache::gather::GatherPoint;
use crate::cache::RecordId;
use crate::store::{decode_value, encode};
use glam::Vec3;

/// The method-wide state.
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct GlobalState {
    next_id: u64,
}

pub(crate) fn encode_next_id(next_id: RecordId) -> Vec<u8> {
    encode(&GlobalState { next_id })
}

/// The records of `state` decoded by `decode` and the next record id,
/// checked: each record holds the id it is stored under, below the next
/// id, in increasing order. Errors name `method` and the record.
pub(crate) fn restore<R>(
    method: &str,
    state: &MethodState,
    mut decode: impl FnMut(&[u8]) -> Result<R, String>,
    id_of: impl Fn(&R) -> RecordId,
) -> Result<(Vec<R>, RecordId), StateError> {
    let next_id = decode_value::<GlobalState>(&state.global)
        .map(|g| g.next_id)
        .map_err(|e| StateError {
            record: None,
            detail: format!("{method} state: {e}"),
        })?;
    let mut records: Vec<R> = Vec::with_capacity(state.records.len());
    for (id, bytes) in &state.records {
        let bad = |detail: String| StateError {
            record: Some(*id),
            detail,
        };
        let r = decode(bytes).map_err(bad)?;
        let held = id_of(&r);
        if held != *id || held >= next_id {
            return Err(bad(format!(
                "record state holds id {held} (next id {next_id})"
            )));
        }
        if records.last().is_some_and(|p| id_of(p) >= held) {
            return Err(bad("records out of id order".into()));
        }
        records.push(r);
    }
    Ok((records, next_id))
}

/// What a carried record of either method must hold to be used: a finite
/// point with normals of unit length, a positive radius and a pixel
/// footprint of at least 0. Bytes that pass rkyv's check may hold any
/// floats, and a NaN point or radius would make NaN records and the
/// octree's cells from them. `Err` says what is wrong.
pub(crate) fn check_record_geometry(
    point: &GatherPoint,
    radius: f32,
    footprint: f32,
) -> Result<(), String> {
    let unit = |n: Vec3| n.is_finite() && (n.length() - 1.0).abs() < 1e-3;
    if !point.position.is_finite() {
        return Err("a point that is not finite".into());
    }
    if !unit(point.normal) || !unit(point.geometric_normal) {
        return Err("a normal that is not of unit length".into());
    }
    if !(radius.is_finite() && radius > 0.0 && footprint.is_finite() && footprint >= 0.0) {
        return Err("a radius or pixel footprint out of range".into());
    }
    Ok(())
}
