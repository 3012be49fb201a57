//! `trc`'s carried state as bytes for the store
//! ([`StateChanges`](crate::method::StateChanges)): rkyv
//! archives, validated when read back. The layout is part of the store
//! schema (`migrations/`): changing it needs a migration.

use super::TemporalRecord;
use crate::cache::gather::GatherPoint;
use crate::cache::IrradianceRecord;
use crate::method::carried::aligned;
use crate::method::ic::Candidate;
use glam::Vec3;
use rkyv::rancor;

/// Everything of a [`TemporalRecord`], in plain arrays.
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
pub(super) struct RecordState {
    id: u64,
    created_frame: u32,
    object: u32,
    position: [f32; 3],
    normal: [f32; 3],
    irradiance: [f32; 3],
    grad_translation: [[f32; 3]; 3],
    grad_rotation: [[f32; 3]; 3],
    /// As clamped by the latest cache the record was in.
    radius: f32,
    pixel: u32,
    stream: u64,
    point_position: [f32; 3],
    point_normal: [f32; 3],
    point_geometric_normal: [f32; 3],
    footprint: f32,
    next_irradiance: [f32; 3],
    change: f32,
    last_valid: u32,
    d_irradiance: [f32; 3],
    d_grad_rotation: [[f32; 3]; 3],
    d_grad_translation: [[f32; 3]; 3],
    replaces: Option<u64>,
    used: bool,
}

fn a(v: Vec3) -> [f32; 3] {
    v.to_array()
}

fn a3(v: [Vec3; 3]) -> [[f32; 3]; 3] {
    v.map(|v| v.to_array())
}

fn v3(a: [[f32; 3]; 3]) -> [Vec3; 3] {
    a.map(Vec3::from)
}

pub(super) fn encode_record(r: &TemporalRecord) -> Vec<u8> {
    let c = &r.candidate;
    let s = RecordState {
        id: r.record.id,
        created_frame: r.record.created_frame,
        object: r.record.object,
        position: a(r.record.position),
        normal: a(r.record.normal),
        irradiance: a(r.record.irradiance),
        grad_translation: a3(r.record.grad_translation),
        grad_rotation: a3(r.record.grad_rotation),
        radius: r.record.radius,
        pixel: c.pixel,
        stream: c.stream,
        point_position: a(c.point.position),
        point_normal: a(c.point.normal),
        point_geometric_normal: a(c.point.geometric_normal),
        footprint: c.footprint,
        next_irradiance: a(r.next_irradiance),
        change: r.change,
        last_valid: r.last_valid,
        d_irradiance: a(r.d_irradiance),
        d_grad_rotation: a3(r.d_grad_rotation),
        d_grad_translation: a3(r.d_grad_translation),
        replaces: r.replaces,
        used: r.used,
    };
    rkyv::to_bytes::<rancor::Error>(&s)
        .expect("serialising plain data to memory cannot fail")
        .into_vec()
}

pub(super) fn decode_record(bytes: &[u8]) -> Result<TemporalRecord, String> {
    let aligned = aligned(bytes);
    let s = rkyv::from_bytes::<RecordState, rancor::Error>(&aligned)
        .map_err(|e| format!("trc record state: {e}"))?;
    if s.last_valid < s.created_frame {
        return Err(format!(
            "trc record state: last valid frame {} before its creation {}",
            s.last_valid, s.created_frame
        ));
    }
    Ok(TemporalRecord {
        record: IrradianceRecord {
            id: s.id,
            position: s.position.into(),
            normal: s.normal.into(),
            irradiance: s.irradiance.into(),
            grad_translation: v3(s.grad_translation),
            grad_rotation: v3(s.grad_rotation),
            radius: s.radius,
            created_frame: s.created_frame,
            object: s.object,
            eas: None,
        },
        candidate: Candidate {
            pixel: s.pixel,
            stream: s.stream,
            point: GatherPoint {
                position: s.point_position.into(),
                normal: s.point_normal.into(),
                geometric_normal: s.point_geometric_normal.into(),
            },
            object: s.object,
            footprint: s.footprint,
            glossy: None,
        },
        next_irradiance: s.next_irradiance.into(),
        change: s.change,
        last_valid: s.last_valid,
        d_irradiance: s.d_irradiance.into(),
        d_grad_rotation: v3(s.d_grad_rotation),
        d_grad_translation: v3(s.d_grad_translation),
        replaces: s.replaces,
        used: s.used,
    })
}
