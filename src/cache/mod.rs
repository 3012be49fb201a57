//! The record cache of the methods that cache irradiance (`ic`, and `trc`
//! and `tcg`, which carry its records across frames): irradiance records
//! with gradients ([`record`]), hemisphere gathering ([`gather`]), a spatial
//! index over their spheres of influence ([`octree`]) and the weighted
//! interpolation of TRC paper Eq. 1–4 ([`IrradianceCache::interpolate`]).

pub mod eas;
pub mod gather;
pub mod octree;
pub mod record;

use glam::Vec3;
use octree::SphereOctree;
pub use record::{IrradianceRecord, LookupPoint, RecordId, WEIGHT_CAP};

/// Records of one cache with their spatial index.
pub struct IrradianceCache {
    /// User accuracy `a`: a record is used where `w ≥ 1/a` (Ward 1988).
    pub accuracy: f32,
    records: Vec<IrradianceRecord>,
    index: SphereOctree,
}

/// An interpolated irradiance and how many records made it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Interpolated {
    pub irradiance: Vec3,
    pub records: u32,
}

impl IrradianceCache {
    /// An empty cache for a scene within `[min, max]`.
    pub fn new(min: Vec3, max: Vec3, accuracy: f32) -> Self {
        IrradianceCache {
            accuracy,
            records: Vec::new(),
            index: SphereOctree::new(min, max),
        }
    }

    pub fn records(&self) -> &[IrradianceRecord] {
        &self.records
    }

    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Bytes the cache holds: its records with their sources, and its
    /// index.
    pub fn memory_bytes(&self) -> usize {
        self.records.capacity() * std::mem::size_of::<IrradianceRecord>()
            + self
                .records
                .iter()
                .map(IrradianceRecord::sources_bytes)
                .sum::<usize>()
            + self.index.memory_bytes()
    }

    /// Calls `visit(record, weight)` for every record usable at `at`:
    /// `w_K(p) ≥ 1/a` (TRC Eq. 3) and not in front of `p`.
    pub fn for_each_usable(&self, at: &LookupPoint, mut visit: impl FnMut(&IrradianceRecord, f32)) {
        self.for_each_usable_indexed(at, |_, record, w| visit(record, w));
    }

    /// [`Self::for_each_usable`] with each record's index in [`Self::records`].
    pub fn for_each_usable_indexed(
        &self,
        at: &LookupPoint,
        mut visit: impl FnMut(usize, &IrradianceRecord, f32),
    ) {
        let threshold = 1.0 / self.accuracy;
        self.index.query(at.position, |i| {
            let record = &self.records[i as usize];
            if let Some(w) = usable_weight(record, at, threshold) {
                visit(i as usize, record, w);
            }
        });
    }

    /// Whether some record can be used at `at` (the test of
    /// [`Self::for_each_usable`], stopping at the first record that passes).
    pub fn covers(&self, at: &LookupPoint) -> bool {
        let threshold = 1.0 / self.accuracy;
        self.index.any(at.position, |i| {
            usable_weight(&self.records[i as usize], at, threshold).is_some()
        })
    }

    /// TRC Eq. 1 with Eq. 4: `E(p) = Σ w_K E_K(p) / Σ w_K` over usable
    /// records; `None` where no record is usable.
    pub fn interpolate(&self, at: &LookupPoint, use_gradients: bool) -> Option<Interpolated> {
        self.interpolate_marking(at, use_gradients, |_| ())
    }

    /// [`Self::interpolate`], calling `mark(index)` for every record used
    /// (`trc` keeps the records that contributed to a frame).
    pub fn interpolate_marking(
        &self,
        at: &LookupPoint,
        use_gradients: bool,
        mut mark: impl FnMut(usize),
    ) -> Option<Interpolated> {
        let (mut sum, mut weights, mut count) = (Vec3::ZERO, 0.0f32, 0u32);
        self.for_each_usable_indexed(at, |i, record, w| {
            mark(i);
            let w = w.min(WEIGHT_CAP);
            sum += record.extrapolate(at.position, at.normal, use_gradients) * w;
            weights += w;
            count += 1;
        });
        (count > 0).then(|| Interpolated {
            irradiance: sum / weights,
            records: count,
        })
    }

    /// Adds a record without neighbour clamping: for records that were
    /// clamped when first inserted and come back in a later frame (`trc`,
    /// `tcg`).
    pub fn insert_as_is(&mut self, record: IrradianceRecord) {
        let id = self.records.len() as u32;
        self.index
            .insert(id, record.position, record.influence_radius(self.accuracy));
        self.records.push(record);
    }

    /// Adds a record, with neighbour clamping (Křivánek et al. 2006,
    /// "Making radiance and irradiance caching practical", §4): radii of
    /// neighbouring records may not differ by more than their distance,
    /// `R_k ≤ R_j + ‖p_k − p_j‖` both ways, which keeps a small record from
    /// sitting inside a huge one that ignores the geometry it saw.
    pub fn insert(&mut self, mut record: IrradianceRecord) {
        let mut neighbours = Vec::new();
        self.index.query(record.position, |i| neighbours.push(i));
        for &j in &neighbours {
            let other = &self.records[j as usize];
            let d = (other.position - record.position).length();
            record.radius = record.radius.min(other.radius + d);
        }
        for &j in &neighbours {
            let other = &mut self.records[j as usize];
            let d = (other.position - record.position).length();
            let clamped = other.radius.min(record.radius + d);
            if clamped < other.radius {
                other.radius = clamped;
                let (p, r) = (other.position, other.influence_radius(self.accuracy));
                self.index.shrink(j, p, r);
            }
        }
        let id = self.records.len() as u32;
        self.index
            .insert(id, record.position, record.influence_radius(self.accuracy));
        self.records.push(record);
    }
}

/// The weight of `record` at `at` if it may be used there (TRC Eq. 3:
/// `w ≥ 1/a`, and Ward's in-front test), the test every lookup applies.
fn usable_weight(record: &IrradianceRecord, at: &LookupPoint, threshold: f32) -> Option<f32> {
    let w = record.weight(at);
    (w >= threshold && !record.is_in_front_of(at)).then_some(w)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Rng;

    /// `covers` (which stops at the first usable record) answers as
    /// "some record is usable" does over all of them, on random caches and
    /// lookups near their records.
    #[test]
    fn covers_answers_as_a_full_lookup() {
        let mut rng = Rng::from_seed(11, 0);
        let mut v = || Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let (mut covered, mut open) = (0, 0);
        for _ in 0..20 {
            let mut cache = IrradianceCache::new(Vec3::ZERO, Vec3::ONE, 0.3);
            for id in 0..200 {
                cache.insert(IrradianceRecord {
                    id,
                    position: v(),
                    normal: ((v() - 0.5) * 0.2 + Vec3::Z).normalize(),
                    irradiance: Vec3::ONE,
                    grad_translation: [Vec3::ZERO; 3],
                    grad_rotation: [Vec3::ZERO; 3],
                    radius: 0.1 + 0.5 * v().x,
                    created_frame: 0,
                    object: 0,
                    eas: None,
                });
            }
            for _ in 0..500 {
                let at = LookupPoint::open(v(), ((v() - 0.5) * 0.2 + Vec3::Z).normalize());
                let mut any = false;
                cache.for_each_usable(&at, |_, _| any = true);
                assert_eq!(cache.covers(&at), any);
                *(if any { &mut covered } else { &mut open }) += 1;
            }
        }
        assert!(
            covered > 100 && open > 100,
            "{covered} covered, {open} open"
        );
    }
}
