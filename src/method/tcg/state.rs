//! `tcg`'s carried state as bytes for the store
//! ([`StateChanges`](crate::method::StateChanges)): rkyv archives,
//! validated when read back. A record's state is what its next frame is
//! computed from: where it was made (its candidate and its object's
//! transform then), its radius as last clamped, whether a pixel used it,
//! and its samples: since schema 10
//! (`migrations/0010_tcg_state_refers_to_samples.md`) those of the
//! record's version the same frame stores, before that a copy in the
//! state. Its irradiance and gradients are not kept: every frame computes
//! them again from the samples. The layout is part of the store schema
//! (`migrations/`): changing it needs a migration. Schema 7
//! (`migrations/0007_radiance_records_in_state.md`) added a radiance record's
//! material after what schema 6 stored; [`upgrade_schema_6_record`]
//! converts a schema-6 record.

use super::TcgRecord;
use crate::cache::gather::GatherPoint;
use crate::cache::IrradianceRecord;
use crate::method::carried::check_record_geometry;
use crate::method::ic::Candidate;
use crate::store::rgbe::PackedSample;
use crate::store::samples::SampleBlock;
use crate::store::{aligned, decode_value, encode};
use glam::{Mat4, Vec3};
use rkyv::rancor;
use std::collections::BTreeMap;

#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct RecordState {
    /// All of an irradiance record: the whole of a schema-6 record.
    sampled: SampledState,
    /// The material of a radiance record's surface (`--ic-glossy eas`),
    /// whose sources each frame builds again from the samples.
    glossy: Option<u32>,
}

/// A record but its material: a schema-6 record's layout (frozen:
/// changing it changes schema 6).
#[derive(rkyv::Archive, rkyv::Serialize, rkyv::Deserialize)]
struct SampledState {
    id: u64,
    created_frame: u32,
    object: u32,
    radius: f32,
    pixel: u32,
    stream: u64,
    point_position: [f32; 3],
    point_normal: [f32; 3],
    point_geometric_normal: [f32; 3],
    footprint: f32,
    object_to_world: [f32; 16],
    used: bool,
    sample_count: u32,
    samples_zstd: Vec<u8>,
}

/// The state of `r` but its samples, which the record's version stored by
/// the same frame holds (schema 10: a sample count of 0 and no bytes say
/// so; a frame stores every record's version, and states before schema 10
/// held a copy of the samples, `migrations/0010_tcg_state_refers_to_samples.md`).
pub(super) fn encode_record(r: &TcgRecord) -> Vec<u8> {
    let c = &r.candidate;
    let sampled = SampledState {
        id: r.record.id,
        created_frame: r.record.created_frame,
        object: r.record.object,
        radius: r.record.radius,
        pixel: c.pixel,
        stream: c.stream,
        point_position: c.point.position.to_array(),
        point_normal: c.point.normal.to_array(),
        point_geometric_normal: c.point.geometric_normal.to_array(),
        footprint: c.footprint,
        object_to_world: r.object_to_world.to_cols_array(),
        used: r.used,
        sample_count: 0,
        samples_zstd: Vec::new(),
    };
    encode(&RecordState {
        sampled,
        glossy: c.glossy,
    })
}

/// A record back from its bytes; its samples are its own stored version's,
/// taken out of `stored` (by id: those of the records its frame stored),
/// or, in a state from before schema 10, held in the bytes; they must be
/// `cells` (the job's strata). Position, normal and irradiance are its creation
/// point's and zero until its next frame computes them.
pub(super) fn decode_record(
    bytes: &[u8],
    cells: usize,
    stored: &mut BTreeMap<u64, Vec<PackedSample>>,
) -> Result<TcgRecord, String> {
    let RecordState { sampled: s, glossy } =
        decode_value::<RecordState>(bytes).map_err(|e| format!("tcg record state: {e}"))?;
    let samples = if s.sample_count == 0 && s.samples_zstd.is_empty() {
        stored.remove(&s.id).ok_or_else(|| {
            format!(
                "tcg record state: record {} has no samples among those its frame stored",
                s.id
            )
        })?
    } else {
        SampleBlock::unpack_bytes(&s.samples_zstd, s.sample_count)
            .map_err(|e| format!("tcg record state: samples: {e}"))?
    };
    if samples.len() != cells {
        return Err(format!(
            "tcg record state: {} samples, the job's strata have {cells} cells",
            samples.len()
        ));
    }
    let object_to_world = Mat4::from_cols_array(&s.object_to_world);
    let point = GatherPoint {
        position: s.point_position.into(),
        normal: s.point_normal.into(),
        geometric_normal: s.point_geometric_normal.into(),
    };
    if !object_to_world.is_finite() {
        return Err("tcg record state: a transform that is not finite".into());
    }
    check_record_geometry(&point, s.radius, s.footprint)
        .map_err(|e| format!("tcg record state: {e}"))?;
    Ok(TcgRecord {
        record: IrradianceRecord {
            id: s.id,
            position: point.position,
            normal: point.normal,
            irradiance: Vec3::ZERO,
            grad_translation: [Vec3::ZERO; 3],
            grad_rotation: [Vec3::ZERO; 3],
            radius: s.radius,
            created_frame: s.created_frame,
            object: s.object,
            eas: None,
        },
        candidate: Candidate {
            pixel: s.pixel,
            stream: s.stream,
            point,
            object: s.object,
            footprint: s.footprint,
            glossy,
        },
        object_to_world,
        samples,
        used: s.used,
    })
}

/// Whether a record's bytes are a radiance record's (`inspect` counts a
/// job's radiance records with it).
pub fn is_radiance_record(bytes: &[u8]) -> Result<bool, String> {
    let aligned = aligned(bytes);
    let s = rkyv::access::<ArchivedRecordState, rancor::Error>(&aligned)
        .map_err(|e| format!("tcg record state: {e}"))?;
    Ok(s.glossy.is_some())
}

/// A schema-6 record's bytes in the schema-7 layout: the same record, an
/// irradiance record (schema 6 had no `tcg` radiance records).
pub fn upgrade_schema_6_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let sampled = decode_value::<SampledState>(bytes)
        .map_err(|e| format!("schema-6 tcg record state: {e}"))?;
    Ok(encode(&RecordState {
        sampled,
        glossy: None,
    }))
}

/// A record's state holding `samples`, its samples, as schemas 6–9 wrote
/// it, for tests of the resume from such a state.
#[doc(hidden)]
pub fn with_samples_as_schema_9(bytes: &[u8], samples: &[PackedSample]) -> Result<Vec<u8>, String> {
    let mut s = decode_value::<RecordState>(bytes).map_err(|e| format!("tcg record state: {e}"))?;
    let block = SampleBlock::from_packed(samples);
    (s.sampled.sample_count, s.sampled.samples_zstd) = (block.count, block.zstd);
    Ok(encode(&s))
}

/// A schema-7 irradiance record's bytes in the schema-6 layout, for tests
/// of the migration.
#[doc(hidden)]
pub fn downgrade_to_schema_6_record(bytes: &[u8]) -> Result<Vec<u8>, String> {
    let s = decode_value::<RecordState>(bytes).map_err(|e| format!("tcg record state: {e}"))?;
    if s.glossy.is_some() {
        return Err(format!("record {} is a radiance record", s.sampled.id));
    }
    Ok(encode(&s.sampled))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record() -> TcgRecord {
        let point = GatherPoint {
            position: Vec3::new(0.5, 0.0, -0.25),
            normal: Vec3::Y,
            geometric_normal: Vec3::Y,
        };
        TcgRecord {
            record: IrradianceRecord {
                id: 7,
                position: point.position,
                normal: point.normal,
                irradiance: Vec3::ONE,
                grad_translation: [Vec3::ZERO; 3],
                grad_rotation: [Vec3::ZERO; 3],
                radius: 0.3,
                created_frame: 2,
                object: 1,
                eas: None,
            },
            candidate: Candidate {
                pixel: 40,
                stream: 99,
                point,
                object: 1,
                footprint: 0.01,
                glossy: None,
            },
            object_to_world: Mat4::from_translation(Vec3::X),
            samples: (0..12)
                .map(|i| PackedSample::pack(Vec3::splat(i as f32), 1.5, 3, i % 2 == 0, i))
                .collect(),
            used: true,
        }
    }

    /// `r`'s samples as the store hands them to a resume: by id.
    fn stored(r: &TcgRecord) -> BTreeMap<u64, Vec<PackedSample>> {
        BTreeMap::from([(r.record.id, r.samples.clone())])
    }

    /// `r`'s state as schemas 6–9 stored it, holding its samples.
    fn encoded_with_samples(r: &TcgRecord) -> Vec<u8> {
        with_samples_as_schema_9(&encode_record(r), &r.samples).unwrap()
    }

    /// What the next frame is computed from comes back as it was, its
    /// samples from its stored version (or, from before schema 10, from
    /// the state itself); a state of other strata, one whose samples are
    /// not stored, a NaN point, a normal that is not a unit vector or a
    /// radius of zero is refused with a message, and garbage too.
    #[test]
    fn a_record_state_round_trips_and_bad_ones_are_refused() {
        let r = record();
        let no_samples = BTreeMap::new();
        for (bytes, samples) in [
            (encode_record(&r), stored(&r)),
            (encoded_with_samples(&r), no_samples.clone()),
        ] {
            let back = decode_record(&bytes, 12, &mut samples.clone()).unwrap();
            assert_eq!(back.samples, r.samples);
            assert_eq!(back.object_to_world, r.object_to_world);
            assert_eq!(back.candidate.point.position, r.candidate.point.position);
            assert_eq!(
                (back.record.id, back.record.radius, back.used),
                (7, 0.3, true)
            );
            assert!(decode_record(&bytes, 48, &mut samples.clone())
                .unwrap_err()
                .contains("12 samples"));
        }
        assert!(encode_record(&r).len() < encoded_with_samples(&r).len());
        assert!(
            decode_record(&encode_record(&r), 12, &mut no_samples.clone())
                .unwrap_err()
                .contains("record 7 has no samples among those its frame stored")
        );
        let bad = |change: fn(&mut TcgRecord)| {
            let mut r = record();
            change(&mut r);
            decode_record(&encode_record(&r), 12, &mut stored(&r)).unwrap_err()
        };
        assert!(bad(|r| r.candidate.point.position.x = f32::NAN).contains("not finite"));
        assert!(bad(|r| r.candidate.point.normal = Vec3::ZERO).contains("unit length"));
        assert!(bad(|r| r.record.radius = 0.0).contains("radius"));
        assert!(decode_record(b"garbage", 12, &mut no_samples.clone()).is_err());
    }
}
