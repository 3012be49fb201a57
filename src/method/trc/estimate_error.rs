//! How well a record's estimate of `E(t0+1)` predicts the irradiance it
//! will really have one frame after it was gathered (TRC Table 1): the
//! estimate sets `τ`, hence the record's life (Eq. 7–11) and its extrapolated
//! temporal gradients (Eq. 15–17), so its error is what reprojection (§4.7)
//! is for. The actual `E(t0+1)` is gathered again at the record's point with
//! the record's own random streams ([`super::TemporalRadianceCaching::regather`]),
//! so samples that did not change cancel and what is left is the estimate's
//! own error. `radcache bench --estimate-error` reports it over every record
//! a `trc` run computes; `tests/trc.rs` over the records of single frames.

use super::TemporalRecord;
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
/// [`estimate_errors`], as fractions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimateError {
    pub records: u64,
    /// The estimate the records carry (reprojected, unless reprojection is
    /// off: then it is the constant one).
    pub estimate: (f32, f32),
    /// The constant estimate, `E(t0+1) = E(t0)`.
    pub constant: (f32, f32),
}

/// Collects the errors of a run's records frame by frame, relative to the
/// mean actual irradiance of all of them: after the first frame a run
/// computes few records a frame, mostly replacements where the light
/// changed, whose own mean would be a poor yardstick.
#[derive(Clone, Debug, Default)]
pub struct EstimateErrorTally {
    /// Per record, [`estimate_errors`] before the division by the mean.
    absolute: Vec<(f32, f32)>,
    /// Sum of the records' actual irradiance, mean over the channels.
    actual_sum: f64,
}

impl EstimateErrorTally {
    /// Adds the records of one frame and their actual `E(t0+1)`.
    pub fn add(&mut self, records: &[TemporalRecord], actual: &[Vec3]) {
        self.absolute.extend(absolute_errors(records, actual));
        self.actual_sum += f64::from(mean_irradiance(actual)) * actual.len() as f64;
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
        Some(EstimateError {
            records: estimate.len() as u64,
            estimate: mean_and_median(&mut estimate)?,
            constant: mean_and_median(&mut constant)?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tally_of_nothing_has_no_summary() {
        assert_eq!(EstimateErrorTally::default().summary(), None);
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
