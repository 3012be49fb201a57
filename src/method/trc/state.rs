//! `trc`'s carried state as bytes for the store
//! ([`StateChanges`](crate::method::StateChanges)): rkyv
//! archives, validated when read back. The layout is part of the store
//! schema (`migrations/`): changing it needs a migration. Schema 7
//! (`migrations/0007_radiance_records_in_state.md`) added a radiance record's
//! material and sources after what schema 6 stored of a record
//! ([`upgrade_schema_6_record`]); schema 11
//! (`migrations/0011_trc_state_without_spatial_gradient_changes.md`)
//! dropped the extrapolated changes of the spatial gradients, which no
//! frame applies ([`TemporalRecord::at_frame`]'s departure from TRC Eq.
//! 16–17; [`upgrade_schema_10_record`]); schema 12
//! (`migrations/0012_trc_state_without_derived_change.md`) dropped the
//! change to the next frame and the temporal gradient of E, which follow
//! from E(t0), E(t0+1) and the sources' changes
//! ([`TemporalRecord::change`], [`TemporalRecord::d_irradiance`];
//! [`upgrade_schema_11_record`]).

use super::TemporalRecord;
use crate::cache::eas::Eas;
use crate::cache::gather::GatherPoint;
use crate::cache::IrradianceRecord;
use crate::method::carried::check_record_geometry;
use crate::method::ic::Candidate;
use crate::store::{aligned, decode_value, encode};
use glam::Vec3;
use rkyv::rancor;

/// Everything of a [`TemporalRecord`], in plain arrays (schema 12).
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct RecordState {
    /// All of an irradiance record.
    irradiance: IrradianceState,
    /// The material of a radiance record's surface (`--ic-glossy eas`),
    /// which a replacement gathers again with.
    glossy: Option<u32>,
    /// A radiance record's sources, with their temporal gradients.
    eas: Option<Vec<EasState>>,
}

/// Everything of a [`TemporalRecord`] but its radiance-record parts.
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct IrradianceState {
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
    last_valid: u32,
    replaces: Option<u64>,
    used: bool,
}

/// A record of schema 11 (frozen: the migration to schema 12 reads it):
/// [`RecordState`] with [`IrradianceStateSchema11`].
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct RecordStateSchema11 {
    irradiance: IrradianceStateSchema11,
    glossy: Option<u32>,
    eas: Option<Vec<EasState>>,
}

/// The irradiance part of a record of schema 11 (frozen):
/// [`IrradianceState`] with the change to the next frame and the temporal
/// gradient of E, both derived from what the record keeps besides.
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct IrradianceStateSchema11 {
    id: u64,
    created_frame: u32,
    object: u32,
    position: [f32; 3],
    normal: [f32; 3],
    irradiance: [f32; 3],
    grad_translation: [[f32; 3]; 3],
    grad_rotation: [[f32; 3]; 3],
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
    replaces: Option<u64>,
    used: bool,
}

/// A record of schemas 7–10 (frozen: the migration to schema 11 reads
/// it): [`RecordState`] with [`IrradianceStateSchema6`].
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct RecordStateSchema7 {
    irradiance: IrradianceStateSchema6,
    glossy: Option<u32>,
    eas: Option<Vec<EasState>>,
}

/// A record of schema 6, and the irradiance part of schemas 7–10
/// (frozen): [`IrradianceState`] with the extrapolated changes of the
/// spatial gradients (TRC Eq. 16–17) after `d_irradiance`.
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct IrradianceStateSchema6 {
    id: u64,
    created_frame: u32,
    object: u32,
    position: [f32; 3],
    normal: [f32; 3],
    irradiance: [f32; 3],
    grad_translation: [[f32; 3]; 3],
    grad_rotation: [[f32; 3]; 3],
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

impl IrradianceStateSchema6 {
    /// The record without its spatial gradients' changes (schema 11).
    fn upgraded(self) -> IrradianceStateSchema11 {
        IrradianceStateSchema11 {
            id: self.id,
            created_frame: self.created_frame,
            object: self.object,
            position: self.position,
            normal: self.normal,
            irradiance: self.irradiance,
            grad_translation: self.grad_translation,
            grad_rotation: self.grad_rotation,
            radius: self.radius,
            pixel: self.pixel,
            stream: self.stream,
            point_position: self.point_position,
            point_normal: self.point_normal,
            point_geometric_normal: self.point_geometric_normal,
            footprint: self.footprint,
            next_irradiance: self.next_irradiance,
            change: self.change,
            last_valid: self.last_valid,
            d_irradiance: self.d_irradiance,
            replaces: self.replaces,
            used: self.used,
        }
    }

    /// `s` as an older build wrote it, its spatial gradients' changes 0
    /// (for tests of the migrations).
    fn downgraded(s: IrradianceStateSchema11) -> Self {
        IrradianceStateSchema6 {
            id: s.id,
            created_frame: s.created_frame,
            object: s.object,
            position: s.position,
            normal: s.normal,
            irradiance: s.irradiance,
            grad_translation: s.grad_translation,
            grad_rotation: s.grad_rotation,
            radius: s.radius,
            pixel: s.pixel,
            stream: s.stream,
            point_position: s.point_position,
            point_normal: s.point_normal,
            point_geometric_normal: s.point_geometric_normal,
            footprint: s.footprint,
            next_irradiance: s.next_irradiance,
            change: s.change,
            last_valid: s.last_valid,
            d_irradiance: s.d_irradiance,
            d_grad_rotation: [[0.0; 3]; 3],
            d_grad_translation: [[0.0; 3]; 3],
            replaces: s.replaces,
            used: s.used,
        }
    }
}

impl IrradianceStateSchema11 {
    /// The record without what follows from the rest (schema 12).
    fn upgraded(self) -> IrradianceState {
        IrradianceState {
            id: self.id,
            created_frame: self.created_frame,
            object: self.object,
            position: self.position,
            normal: self.normal,
            irradiance: self.irradiance,
            grad_translation: self.grad_translation,
            grad_rotation: self.grad_rotation,
            radius: self.radius,
            pixel: self.pixel,
            stream: self.stream,
            point_position: self.point_position,
            point_normal: self.point_normal,
            point_geometric_normal: self.point_geometric_normal,
            footprint: self.footprint,
            next_irradiance: self.next_irradiance,
            last_valid: self.last_valid,
            replaces: self.replaces,
            used: self.used,
        }
    }

    /// `r`'s state `s` as a schema-11 build wrote it, with `r`'s change
    /// and temporal gradient of E (for tests of the migrations).
    fn downgraded(s: IrradianceState, r: &TemporalRecord) -> Self {
        IrradianceStateSchema11 {
            id: s.id,
            created_frame: s.created_frame,
            object: s.object,
            position: s.position,
            normal: s.normal,
            irradiance: s.irradiance,
            grad_translation: s.grad_translation,
            grad_rotation: s.grad_rotation,
            radius: s.radius,
            pixel: s.pixel,
            stream: s.stream,
            point_position: s.point_position,
            point_normal: s.point_normal,
            point_geometric_normal: s.point_geometric_normal,
            footprint: s.footprint,
            next_irradiance: s.next_irradiance,
            change: r.change(),
            last_valid: s.last_valid,
            d_irradiance: a(r.d_irradiance()),
            replaces: s.replaces,
            used: s.used,
        }
    }
}

/// One source of a radiance record ([`Eas`]) and its extrapolated temporal
/// gradient.
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct EasState {
    offset: [f32; 3],
    solid_angle: f32,
    irradiance: [f32; 3],
    node: u32,
    d_irradiance: [f32; 3],
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
    encode(&state_of(r))
}

/// `r` in the layout of this schema.
fn state_of(r: &TemporalRecord) -> RecordState {
    let c = &r.candidate;
    let irradiance = IrradianceState {
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
        last_valid: r.last_valid,
        replaces: r.replaces,
        used: r.used,
    };
    let eas = r.record.eas.as_ref().map(|sources| {
        let d = r.d_eas.as_deref().unwrap_or(&[]);
        sources
            .iter()
            .enumerate()
            .map(|(i, e)| EasState {
                offset: a(e.offset),
                solid_angle: e.solid_angle,
                irradiance: a(e.irradiance),
                node: e.node,
                d_irradiance: a(d.get(i).copied().unwrap_or(Vec3::ZERO)),
            })
            .collect()
    });
    RecordState {
        irradiance,
        glossy: c.glossy,
        eas,
    }
}

pub(super) fn decode_record(bytes: &[u8]) -> Result<TemporalRecord, String> {
    let RecordState {
        irradiance: s,
        glossy,
        eas,
    } = decode_value::<RecordState>(bytes).map_err(|e| format!("trc record state: {e}"))?;
    if s.last_valid < s.created_frame || s.last_valid == u32::MAX {
        return Err(format!(
            "trc record state: last valid frame {} before its creation {} or past the last frame",
            s.last_valid, s.created_frame
        ));
    }
    let sources = eas.as_ref().map(|sources| {
        sources
            .iter()
            .map(|e| Eas {
                offset: e.offset.into(),
                solid_angle: e.solid_angle,
                irradiance: e.irradiance.into(),
                node: e.node,
            })
            .collect()
    });
    let d_eas = eas.map(|sources| sources.iter().map(|e| e.d_irradiance.into()).collect());
    let r = TemporalRecord {
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
            eas: sources,
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
            glossy,
        },
        next_irradiance: s.next_irradiance.into(),
        last_valid: s.last_valid,
        d_eas,
        replaces: s.replaces,
        used: s.used,
        // The store keeps no paths: a resumed render's first replacements
        // trace every path, as the kept ones would have gone.
        paths: None,
    };
    check_values(&r).map_err(|e| format!("trc record state: {e}"))?;
    Ok(r)
}

/// What [`check_record_geometry`] checks, and that every irradiance,
/// gradient and source is finite (the change to the next frame that
/// follows may be infinite: a channel dark at t0 that lights up,
/// [`super::record`]).
fn check_values(r: &TemporalRecord) -> Result<(), String> {
    let c = &r.candidate;
    check_record_geometry(&c.point, r.record.radius, c.footprint)?;
    let record = &r.record;
    let vectors = [record.position, record.normal, record.irradiance]
        .into_iter()
        .chain(record.grad_translation)
        .chain(record.grad_rotation)
        .chain([r.next_irradiance])
        .chain(r.d_eas.as_deref().unwrap_or(&[]).iter().copied());
    let sources = record.eas.as_deref().unwrap_or(&[]);
    let finite = vectors.into_iter().all(Vec3::is_finite)
        && sources
            .iter()
            .all(|e| e.offset.is_finite() && e.irradiance.is_finite() && e.solid_angle.is_finite());
    if !finite {
        return Err("an irradiance, gradient or source that is not finite".into());
    }
    Ok(())
}

/// How many sources a record's bytes hold: `None` for an irradiance
/// record (`inspect` counts a job's radiance records with it).
pub fn sources_in(bytes: &[u8]) -> Result<Option<usize>, String> {
    let aligned = aligned(bytes);
    let s = rkyv::access::<ArchivedRecordState, rancor::Error>(&aligned)
        .map_err(|e| format!("trc record state: {e}"))?;
    Ok(s.eas.as_ref().map(|sources| sources.len()))
}

/// A schema-6 record's bytes in the schema-7 layout (that of schemas
/// 7–10): the same record, an irradiance record (schema 6 had no `trc`
/// radiance records).
pub fn upgrade_schema_6_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let irradiance = decode_value::<IrradianceStateSchema6>(bytes)
        .map_err(|e| format!("schema-6 trc record state: {e}"))?;
    Ok(encode(&RecordStateSchema7 {
        irradiance,
        glossy: None,
        eas: None,
    }))
}

/// A record's bytes of schemas 7–10 in the schema-11 layout: the same
/// record without the changes of its spatial gradients.
pub fn upgrade_schema_10_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let s = decode_value::<RecordStateSchema7>(bytes)
        .map_err(|e| format!("schema-10 trc record state: {e}"))?;
    Ok(encode(&RecordStateSchema11 {
        irradiance: s.irradiance.upgraded(),
        glossy: s.glossy,
        eas: s.eas,
    }))
}

/// A record's bytes of schema 11 in the schema-12 layout: the same record
/// without its change to the next frame and temporal gradient of E, which
/// follow from the rest.
pub fn upgrade_schema_11_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let s = decode_value::<RecordStateSchema11>(bytes)
        .map_err(|e| format!("schema-11 trc record state: {e}"))?;
    Ok(encode(&RecordState {
        irradiance: s.irradiance.upgraded(),
        glossy: s.glossy,
        eas: s.eas,
    }))
}

/// A record's bytes in the schema-11 layout: what a schema-11 build wrote,
/// for tests of the migrations.
#[doc(hidden)]
pub fn downgrade_to_schema_11_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    Ok(encode(&schema_11_of(bytes)?))
}

fn schema_11_of(bytes: &[u8]) -> Result<RecordStateSchema11, String> {
    let r = decode_record(bytes)?;
    let s = state_of(&r);
    Ok(RecordStateSchema11 {
        irradiance: IrradianceStateSchema11::downgraded(s.irradiance, &r),
        glossy: s.glossy,
        eas: s.eas,
    })
}

/// A record's bytes in the layout of schemas 7–10, the changes of its
/// spatial gradients 0: what a schema-10 build wrote, but for those
/// (which no frame of `trc` revision 18 applies), for tests of the
/// migrations.
#[doc(hidden)]
pub fn downgrade_to_schema_10_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let s = schema_11_of(bytes)?;
    Ok(encode(&RecordStateSchema7 {
        irradiance: IrradianceStateSchema6::downgraded(s.irradiance),
        glossy: s.glossy,
        eas: s.eas,
    }))
}

/// An irradiance record's bytes in the schema-6 layout, the changes of
/// its spatial gradients 0: what a schema-6 build wrote, but for those,
/// for tests of the migrations. A radiance record has no schema-6 form.
#[doc(hidden)]
pub fn downgrade_to_schema_6_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let s = schema_11_of(bytes)?;
    if s.glossy.is_some() || s.eas.is_some() {
        return Err(format!("record {} is a radiance record", s.irradiance.id));
    }
    Ok(encode(&IrradianceStateSchema6::downgraded(s.irradiance)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A record of this schema put in the layout of schema 11, of schemas
    /// 7–10 (and of schema 6) and upgraded again is the same bytes, an irradiance record
    /// and a radiance record alike; bytes already upgraded are refused, not
    /// read as another layout.
    #[test]
    fn older_layouts_upgrade_to_the_same_bytes() {
        let mut radiance = TemporalRecord::test_record(Vec3::ONE, 0.01);
        radiance.candidate.glossy = Some(2);
        let source = |node, e: f32| Eas {
            offset: Vec3::new(0.0, 1.0, node as f32),
            solid_angle: 0.5,
            irradiance: Vec3::splat(e),
            node,
        };
        radiance.record.eas = Some(vec![source(1, 1.0), source(2, 2.0)].into());
        radiance.d_eas = Some(vec![Vec3::splat(0.1), Vec3::splat(-0.1)].into());
        let irradiance = encode_record(&TemporalRecord::test_record(Vec3::ONE, 0.01));
        for bytes in [irradiance.clone(), encode_record(&radiance)] {
            let schema_11 = downgrade_to_schema_11_record(&bytes).unwrap();
            assert!(schema_11.len() > bytes.len());
            assert_eq!(upgrade_schema_11_record(&schema_11).unwrap(), bytes);
            let schema_10 = downgrade_to_schema_10_record(&bytes).unwrap();
            assert!(schema_10.len() > schema_11.len());
            assert_eq!(upgrade_schema_10_record(&schema_10).unwrap(), schema_11);
            for not_older in [&bytes, &schema_11] {
                assert!(upgrade_schema_10_record(not_older).is_err());
            }
            assert!(upgrade_schema_11_record(&bytes).is_err());
        }
        let schema_6 = downgrade_to_schema_6_record(&irradiance).unwrap();
        let schema_7 = upgrade_schema_6_record(&schema_6).unwrap();
        let schema_11 = upgrade_schema_10_record(&schema_7).unwrap();
        assert_eq!(upgrade_schema_11_record(&schema_11).unwrap(), irradiance);
        assert!(downgrade_to_schema_6_record(&encode_record(&radiance)).is_err());
    }

    /// A record whose bytes decode to values no render could use is
    /// refused with what is wrong, not restored into the cache.
    #[test]
    fn records_with_unusable_values_are_refused() {
        let good = TemporalRecord::test_record(Vec3::ONE, 0.01);
        let back = decode_record(&encode_record(&good)).expect("a good record decodes");
        assert_eq!(back.record.irradiance, good.record.irradiance);
        let mut infinite_change = TemporalRecord::test_record(Vec3::ZERO, 0.0);
        infinite_change.next_irradiance = Vec3::ONE;
        let back = decode_record(&encode_record(&infinite_change));
        assert_eq!(
            back.expect("an infinite change is one").change(),
            f32::INFINITY
        );

        type Spoil = fn(&mut TemporalRecord);
        let cases: [(&str, Spoil); 6] = [
            ("irradiance", |r| r.record.irradiance.y = f32::NAN),
            ("gradient", |r| r.record.grad_rotation[1].x = f32::INFINITY),
            ("normal", |r| r.candidate.point.normal = Vec3::ZERO),
            ("radius", |r| r.record.radius = 0.0),
            ("next frame", |r| r.next_irradiance.z = f32::NAN),
            ("last frame", |r| r.last_valid = u32::MAX),
        ];
        for (what, spoil) in cases {
            let mut r = TemporalRecord::test_record(Vec3::ONE, 0.01);
            spoil(&mut r);
            let e = decode_record(&encode_record(&r)).err();
            assert!(
                e.as_deref()
                    .is_some_and(|e| e.starts_with("trc record state: ")),
                "{what}: {e:?}"
            );
        }
    }
}
