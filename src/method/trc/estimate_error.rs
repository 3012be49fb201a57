//! How well a record's estimate of `E(t0+1)` predicts the irradiance it
//! will really have one frame after it was gathered (TRC Table 1): the
//! estimate sets `τ`, hence the record's life (Eq. 7–11) and its extrapolated
//! temporal gradients (Eq. 15–17), so its error is what reprojection (§4.7)
//! is for. The actual `E(t0+1)` is gathered again at the record's point with
//! the record's own random streams ([`super::TemporalRadianceCaching::regather`]),
//! so samples that did not change cancel and what is left is the estimate's
//! own error. `radcache bench --estimate-error` reports it over every record
//! a `trc` run computes, with the lifespans the estimate grants against
//! those the actual change would grant; `tests/trc.rs` over the records of
//! single frames.

use super::{frames_of_validity, relative_change, TemporalRecord};
use glam::Vec3;

/// Per record, the error of its `E(t0+1)` estimate and that of the constant
/// estimate `E(t0)` (no reprojection) against `actual`, RMS over the colour
/// channels, relative to the mean actual irradiance of `records` (the
/// records of one frame): records in the dark would otherwise divide by
/// almost nothing.
pub fn estimate_errors(records: &[TemporalRecord], actual: &[Vec3]) -> Vec<(f32, f32)> {
    let mean = mean_irradiance(actual);
    absolute_errors(records, actual)
        .map(|(estimate, constant)| (estimate / mean, constant / mean))
        .collect()
}

/// [`estimate_errors`] before the division by the mean.
fn absolute_errors<'a>(
    records: &'a [TemporalRecord],
    actual: &'a [Vec3],
) -> impl Iterator<Item = (f32, f32)> + 'a {
    records.iter().zip(actual).map(|(k, &e1)| {
        let rms = |est: Vec3| ((est - e1).length_squared() / 3.0).sqrt();
        (rms(k.next_irradiance), rms(k.record.irradiance))
    })
}

/// Mean over records and colour channels.
fn mean_irradiance(irradiance: &[Vec3]) -> f32 {
    irradiance
        .iter()
        .map(|e| e.element_sum() / 3.0)
        .sum::<f32>()
        / irradiance.len().max(1) as f32
}

/// Mean and median (the upper one of an even count) of `v`, which is
/// sorted in place; `None` when `v` is empty.
pub fn mean_and_median(v: &mut [f32]) -> Option<(f32, f32)> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(f32::total_cmp);
    Some((v.iter().sum::<f32>() / v.len() as f32, v[v.len() / 2]))
}

/// "mean M % median D %" of a [`mean_and_median`] pair of fractions.
pub fn percent((mean, median): (f32, f32)) -> String {
    format!("mean {:.2} % median {:.2} %", 100.0 * mean, 100.0 * median)
}

/// The errors of TRC Table 1 over a set of records: mean and median of
/// [`estimate_errors`], as fractions; and what the estimate makes of the
/// records' lives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimateError {
    pub records: u64,
    /// The estimate the records carry (reprojected, unless reprojection is
    /// off: then it is the constant one).
    pub estimate: (f32, f32),
    /// The constant estimate, `E(t0+1) = E(t0)`.
    pub constant: (f32, f32),
    /// Mean lifespan in frames (t0 included) that the temporal weight
    /// (Eq. 9–11) grants the records (the check of the later frames,
    /// `trc::later`, may end a life sooner): with the change their estimate
    /// predicts, and with the change measured by gathering again. Equal
    /// means say the estimate neither cuts lives short nor stretches them;
    /// the measured change also holds the gathers' Monte Carlo noise
    /// (which cancels only where no sample changed), so it is an upper
    /// bound on the change and its lifespans a lower bound.
    pub lifespan: (f32, f32),
}

/// Collects the errors of a run's records frame by frame, relative to the
/// mean actual irradiance of all of them: after the first frame a run
/// computes few records a frame, mostly replacements where the light
/// changed, whose own mean would be a poor yardstick.
#[derive(Clone, Debug)]
pub struct EstimateErrorTally {
    /// Per record, [`estimate_errors`] before the division by the mean.
    absolute: Vec<(f32, f32)>,
    /// Sum of the records' actual irradiance, mean over the channels.
    actual_sum: f64,
    /// The run's `a^t` and `δt_max`, which turn changes into lifespans.
    temporal_accuracy: f32,
    max_life: u32,
    /// Sums of the lifespans granted by the estimated and the actual change.
    lifespan_sums: (u64, u64),
}

impl EstimateErrorTally {
    /// A tally for the records of a run with `a^t = temporal_accuracy` and
    /// `δt_max = max_life`.
    pub fn new(temporal_accuracy: f32, max_life: u32) -> Self {
        EstimateErrorTally {
            absolute: Vec::new(),
            actual_sum: 0.0,
            temporal_accuracy,
            max_life,
            lifespan_sums: (0, 0),
        }
    }

    /// Adds the records of one frame and their actual `E(t0+1)`.
    pub fn add(&mut self, records: &[TemporalRecord], actual: &[Vec3]) {
        self.absolute.extend(absolute_errors(records, actual));
        self.actual_sum += f64::from(mean_irradiance(actual)) * actual.len() as f64;
        for (k, &e1) in records.iter().zip(actual) {
            let actual_change = relative_change(k.record.irradiance, e1);
            self.lifespan_sums.0 += u64::from(self.lifespan(k.change()));
            self.lifespan_sums.1 += u64::from(self.lifespan(actual_change));
        }
    }

    /// Frames a record whose irradiance changes by `change` a frame lives,
    /// t0 included.
    fn lifespan(&self, change: f32) -> u32 {
        frames_of_validity(change, self.temporal_accuracy, self.max_life) + 1
    }

    /// The figures over every record added; `None` before any, or where
    /// the records see no indirect light at all (nothing to be relative to).
    pub fn summary(&self) -> Option<EstimateError> {
        let mean = (self.actual_sum / self.absolute.len().max(1) as f64) as f32;
        if !(mean > 0.0 && mean.is_finite()) {
            return None;
        }
        let (mut estimate, mut constant): (Vec<f32>, Vec<f32>) = self
            .absolute
            .iter()
            .map(|&(e, c)| (e / mean, c / mean))
            .unzip();
        let n = estimate.len() as f64;
        let (by_estimate, by_actual) = self.lifespan_sums;
        Some(EstimateError {
            records: estimate.len() as u64,
            estimate: mean_and_median(&mut estimate)?,
            constant: mean_and_median(&mut constant)?,
            lifespan: (
                (by_estimate as f64 / n) as f32,
                (by_actual as f64 / n) as f32,
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tally_of_nothing_has_no_summary() {
        assert_eq!(EstimateErrorTally::new(0.05, 20).summary(), None);
    }

    fn record(e0: Vec3, change: f32) -> TemporalRecord {
        TemporalRecord::test_record(e0, change)
    }

    /// With `a^t = 0.05` and `δt_max = 20` (Eq. 9–11): a record predicted
    /// to change 1 % a frame lives 6 frames, one that really changes 6 %
    /// lives 1, and an unchanging one 20; the tally averages both kinds.
    #[test]
    fn lifespans_follow_the_estimated_and_the_actual_change() {
        let e0 = Vec3::ONE;
        let records = [record(e0, 0.01), record(e0, 0.0)];
        let actual = [e0 * 1.06, e0];
        let mut tally = EstimateErrorTally::new(0.05, 20);
        tally.add(&records, &actual);
        let e = tally.summary().unwrap();
        assert_eq!(e.records, 2);
        assert_eq!(e.lifespan, ((6.0 + 20.0) / 2.0, (1.0 + 20.0) / 2.0));
    }

    #[test]
    fn mean_and_median_of_nothing_is_none() {
        assert_eq!(mean_and_median(&mut []), None);
        assert_eq!(
            mean_and_median(&mut [3.0, 1.0, 2.0, 10.0]),
            Some((4.0, 3.0))
        );
    }
}
