//! Which of a record's samples are shot again in a frame (Tawara,
//! Myszkowski & Seidel 2004, §3.2–3.3): how many (Eq. 2), and which cells,
//! drawn without repetition with probability ∝ `2^age`.

use super::TcgSettings;
use crate::cache::gather::Strata;
use crate::sampling::Rng;
use crate::store::rgbe::PackedSample;

/// Eq. 2: `N_update(x) = (τ_max − τ_min)·x + τ_min·N`, `x` the samples that
/// hit moving objects, or whose light moving lights changed or whose path
/// an object moved into (`stale`, by cell; departures: see [`super::stale`]
/// and [`super::crossed`]), `N` all of them; rounded up
/// (so that any `τ_min > 0` refreshes every sample in time) and at most
/// `N`.
pub(super) fn cells_to_update(
    settings: &TcgSettings,
    samples: &[PackedSample],
    stale: impl Fn(usize) -> bool,
) -> usize {
    let total = samples.len();
    let dynamic = (samples.iter().enumerate())
        .filter(|&(cell, s)| s.hit_dynamic() || stale(cell))
        .count();
    let n =
        (settings.tau_max - settings.tau_min) * dynamic as f32 + settings.tau_min * total as f32;
    (n.max(0.0).ceil() as usize).min(total)
}

/// `stale` (by cell of `strata`'s `θ × φ` grid, one of `samples` each)
/// grown by one cell along θ and φ (φ wraps round) across edges: a cell
/// beside a stale one becomes stale where their samples lie apart
/// ([`apart`]: one missed and the other hit, or their hits' distances
/// differ by over [`EDGE`]).
///
/// Why: which cells are stale depends on what their samples hit, so a
/// cell across the edge of what is stale (a wall's top edge against the
/// sky under a light that turns: the wall's hits are stale, the sky's
/// misses are not) would be shot again while its sample hits the stale
/// side and kept once a new direction in it missed that side, until
/// `τ_min`'s share came round: its sample drifts to the side that is not
/// stale, and the record with it (on a courtyard under a swinging light,
/// `tests/tcg.rs`, 2.3 times the block bias of shooting every sample again
/// each frame). With its neighbours across the edge, such a cell is stale
/// whichever side its own sample hit, so whether it is shot again no
/// longer follows its own sample. Where neighbouring hits lie on one
/// surface, what is stale changes smoothly along it (the light test
/// depends on the hit's place and age only) and a cell's drift changes
/// little: growing there too, the bound and the neighbours took 38 % more
/// rays than before them under the built-in moving light, against 22 %,
/// for no less error (`benches/RESULTS.md`). A grid that is not
/// `strata`'s (a damaged state) is left as it is.
pub(super) fn with_neighbours(
    stale: &[bool],
    samples: &[PackedSample],
    strata: Strata,
) -> Vec<bool> {
    let (m, n) = (strata.theta as usize, strata.phi as usize);
    if stale.len() != m * n || samples.len() != m * n || !stale.contains(&true) {
        return stale.to_vec();
    }
    let mut grown = stale.to_vec();
    for cell in (0..m * n).filter(|&c| stale[c]) {
        let (j, k) = (cell / n, cell % n);
        let (up, down) = ((j > 0).then(|| cell - n), (j + 1 < m).then(|| cell + n));
        let along = [j * n + (k + 1) % n, j * n + (k + n - 1) % n].map(Some);
        for other in along.into_iter().chain([up, down]).flatten() {
            grown[other] |= apart(&samples[cell], &samples[other]);
        }
    }
    grown
}

/// The relative difference of two neighbouring hits' distances past which
/// an edge lies between them ([`with_neighbours`]): well above what the
/// step of a cell makes along a surface facing the record, below the
/// steps of a silhouette.
const EDGE: f32 = 0.1;

/// Whether two neighbouring cells' samples lie across an edge: one missed
/// and the other hit, or their hits' distances differ by more than
/// [`EDGE`] of the nearer.
fn apart(a: &PackedSample, b: &PackedSample) -> bool {
    match (a.is_miss(), b.is_miss()) {
        (false, false) => {
            let (da, db) = (a.distance(), b.distance());
            (da - db).abs() > EDGE * da.min(db)
        }
        (miss_a, miss_b) => miss_a != miss_b,
    }
}

/// `count` distinct cells of `samples`, in increasing order, drawn one
/// after another with probability `2^age` over the sum of `2^age` of the
/// cells not drawn yet: the paper's draw from a c.d.f. rebuilt after each
/// pick (Fig. 4–5).
///
/// Departure, for speed only: rather than rebuild the c.d.f. after each
/// pick (`O(count·N)`, up to 590,000 steps a record at 768 cells when its
/// samples all see moving objects), each cell gets the key `ln(u)/2^age`
/// from its own uniform `u` and the `count` largest keys win (Efraimidis &
/// Spirakis 2006, "Weighted random sampling with a reservoir"): the same
/// distribution of draws without repetition, in `O(N)`. The unit test
/// checks it against the sequential draw's exact probabilities. The key
/// is ranked by its logarithm, `age·ln 2 − ln(−ln u)` (the same order),
/// since `2^age` leaves `f32` past an age of 127.
///
/// The `first` cells (those moving lights or objects left stale,
/// [`super::stale`], [`super::crossed`]: counted in Eq. 2's `x` to be shot
/// again) are drawn before the others,
/// by age among themselves; the rest of the count by age among the others.
pub(super) fn pick_cells(
    samples: &[PackedSample],
    count: usize,
    rng: &mut Rng,
    first: impl Fn(usize) -> bool,
) -> Vec<u32> {
    if count >= samples.len() {
        return (0..samples.len() as u32).collect();
    }
    if count == 0 {
        return Vec::new();
    }
    let mut keyed: Vec<(bool, f32, u32)> = samples
        .iter()
        .zip(0u32..)
        .map(|(s, cell)| {
            // u ∈ (0, 1]: −ln(u) ∈ [0, ∞), and u = 1 ranks first (+∞).
            let u = 1.0 - rng.next_f32();
            let key = s.age() as f32 * std::f32::consts::LN_2 - (-u.ln()).ln();
            (first(cell as usize), key, cell)
        })
        .collect();
    // `first` cells, then the largest key; equal keys by cell, so the draw
    // is deterministic.
    let by_key = |a: &(bool, f32, u32), b: &(bool, f32, u32)| {
        (b.0.cmp(&a.0))
            .then(b.1.total_cmp(&a.1))
            .then(a.2.cmp(&b.2))
    };
    keyed.select_nth_unstable_by(count - 1, by_key);
    let mut cells: Vec<u32> = keyed[..count].iter().map(|&(_, _, cell)| cell).collect();
    cells.sort_unstable();
    cells
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::SampleKey;
    use glam::Vec3;

    fn aged(ages: &[u32], dynamic: &[bool]) -> Vec<PackedSample> {
        ages.iter()
            .zip(dynamic)
            .map(|(&age, &d)| PackedSample::pack(Vec3::ONE, 1.0, 0, d, age))
            .collect()
    }

    fn rng(i: u32) -> Rng {
        Rng::new(SampleKey {
            seed: 7,
            frame: Some(3),
            item: 11,
            sample: i,
        })
    }

    /// Eq. 2 with the paper's τ_min = 5 %, τ_max = 100 % (§5): 5 % of the
    /// cells plus every one that saw a moving object, at most all.
    #[test]
    fn the_share_updated_follows_equation_2() {
        let settings = TcgSettings::default();
        let fresh = |_: usize| false;
        let still = aged(&[0; 100], &[false; 100]);
        assert_eq!(cells_to_update(&settings, &still, fresh), 5);
        let mut some = [false; 100];
        some[..10].fill(true);
        // 0.95·10 + 0.05·100 = 14.5 → 15.
        assert_eq!(
            cells_to_update(&settings, &aged(&[0; 100], &some), fresh),
            15
        );
        assert_eq!(
            cells_to_update(&settings, &aged(&[0; 100], &[true; 100]), fresh),
            100
        );
        // Stale samples count as those that hit moving objects, once each.
        let stale = |cell: usize| (5..15).contains(&cell);
        assert_eq!(
            cells_to_update(&settings, &aged(&[0; 100], &some), stale),
            20 // 0.95·15 + 5 = 19.25 → 20
        );
        let none = TcgSettings {
            tau_min: 0.0,
            ..TcgSettings::default()
        };
        assert_eq!(cells_to_update(&none, &still, fresh), 0);
    }

    /// A stale cell makes its four neighbours stale (φ wrapping round, θ
    /// not past the pole or the horizon) where their samples lie across an
    /// edge from its own (a miss beside a hit, a hit 20 % farther), and
    /// nothing else: not a neighbour on the same surface (5 % farther), nor
    /// a miss beside a miss; no stale cell, or a grid that is not the
    /// strata's, changes nothing.
    #[test]
    fn a_stale_cell_makes_its_neighbours_across_an_edge_stale() {
        let strata = Strata { theta: 3, phi: 4 };
        let cells = |marked: &[usize]| {
            let mut v = vec![false; 12];
            marked.iter().for_each(|&c| v[c] = true);
            v
        };
        let hit = |d: f32| PackedSample::pack(Vec3::ONE, d, 0, false, 0);
        let miss = PackedSample::pack(Vec3::ZERO, f32::INFINITY, u32::MAX, false, 0);
        assert!(miss.is_miss() && !hit(1.0).is_miss());
        // All across an edge from cell 4 (1, 0) and cell 2 (0, 2).
        let mut samples = vec![miss; 12];
        samples[4] = hit(1.0);
        samples[2] = hit(1.0);
        // (1, 0): (1, 1), (1, 3) round φ, (0, 0) and (2, 0).
        let stale = with_neighbours(&cells(&[4]), &samples, strata);
        assert_eq!(stale, cells(&[4, 5, 7, 0, 8]));
        // (0, 2): no row above the first.
        let stale = with_neighbours(&cells(&[2]), &samples, strata);
        assert_eq!(stale, cells(&[2, 1, 3, 6]));
        // Hits beside cell 4: 1.2 away across an edge, 1.05 on its surface.
        samples = vec![hit(1.05); 12];
        samples[4] = hit(1.0);
        samples[5] = hit(1.2);
        let stale = with_neighbours(&cells(&[4]), &samples, strata);
        assert_eq!(stale, cells(&[4, 5]));
        let stale = with_neighbours(&cells(&[4]), &[miss; 12], strata);
        assert_eq!(stale, cells(&[4]));
        assert_eq!(with_neighbours(&cells(&[]), &samples, strata), cells(&[]));
        assert_eq!(
            with_neighbours(&[true, false], &samples, strata),
            [true, false]
        );
    }

    /// The picks are distinct cells, as many as asked.
    #[test]
    fn picks_are_distinct_and_as_many_as_asked() {
        let samples = aged(&[0, 3, 1, 15, 2, 0, 7, 4], &[false; 8]);
        for count in 0..=9 {
            let cells = pick_cells(&samples, count, &mut rng(count as u32), |_| false);
            assert_eq!(cells.len(), count.min(8));
            assert!(cells.windows(2).all(|w| w[0] < w[1]), "{cells:?}");
        }
    }

    /// Stale cells are drawn first, whatever their age; the rest of the
    /// count goes by age among the others.
    #[test]
    fn stale_cells_are_drawn_first() {
        let samples = aged(&[15, 0, 0, 15, 0, 0, 15, 0], &[false; 8]);
        let stale = |cell: usize| cell == 1 || cell == 4;
        for i in 0..50 {
            assert_eq!(pick_cells(&samples, 2, &mut rng(i), stale), vec![1, 4]);
            let three = pick_cells(&samples, 3, &mut rng(i), stale);
            assert!(three.contains(&1) && three.contains(&4), "{three:?}");
        }
    }

    /// Over 400 frames of a still record (the default `τ_min = 5 %` of 192
    /// cells: 10 a frame, a round in about 20 frames), every sample is
    /// shot again within 1.5 rounds, its age counting every frame: the
    /// paper's Fig. 6 saw at most 14 frames where 10 go round. With ages
    /// that stopped at 15, the draw could not tell the oldest apart and
    /// some waited over 40 frames.
    #[test]
    fn the_oldest_samples_are_shot_again_within_a_round_and_a_half() {
        let settings = TcgSettings::default();
        let mut samples = aged(&[0; 192], &[false; 192]);
        let mut ages = [0u32; 192];
        let mut oldest = 0;
        for frame in 0..400 {
            let count = cells_to_update(&settings, &samples, |_| false);
            assert_eq!(count, 10);
            let cells = pick_cells(&samples, count, &mut rng(frame), |_| false);
            for (cell, s) in samples.iter_mut().enumerate() {
                let shot = cells.binary_search(&(cell as u32)).is_ok();
                *s = if shot {
                    PackedSample { flags: 0, ..*s }
                } else {
                    s.older()
                };
                ages[cell] = if shot { 0 } else { ages[cell] + 1 };
                assert_eq!(s.age(), ages[cell], "frame {frame} cell {cell}");
            }
            oldest = oldest.max(*ages.iter().max().unwrap());
        }
        assert!(oldest <= 30, "a sample waited {oldest} frames");
        assert!(
            oldest >= 20,
            "{oldest}: 10 of 192 a frame cannot go round sooner"
        );
    }

    /// Against the paper's draw (one cell at a time from the c.d.f. of
    /// `2^age` over the cells not drawn yet), computed exactly: with ages
    /// 0, 1, 2 (weights 1, 2, 4) and two picks, the cell left out is cell 0
    /// with probability Σ over the orders of (1,2) = 2/7·4/5 + 4/7·2/3,
    /// and so on. 40,000 draws, within 4 standard deviations.
    #[test]
    fn picks_follow_the_sequential_draw_from_the_age_cdf() {
        let w = [1.0f64, 2.0, 4.0];
        let total: f64 = w.iter().sum();
        // P(cell c is not drawn) = Σ over the first pick f ≠ c of
        // P(f)·P(the other of the two ≠ c, given f).
        let left_out = |c: usize| -> f64 {
            (0..3)
                .filter(|&f| f != c)
                .map(|f| {
                    let other = 3 - c - f;
                    w[f] / total * w[other] / (total - w[f])
                })
                .sum()
        };
        let samples = aged(&[0, 1, 2], &[false; 3]);
        let n = 40_000;
        let mut counts = [0u32; 3];
        for i in 0..n {
            let cells = pick_cells(&samples, 2, &mut rng(i), |_| false);
            let out = (0..3u32).find(|c| !cells.contains(c)).unwrap();
            counts[out as usize] += 1;
        }
        for (c, &count) in counts.iter().enumerate() {
            let p = left_out(c);
            let seen = f64::from(count) / f64::from(n);
            let sd = (p * (1.0 - p) / f64::from(n)).sqrt();
            assert!(
                (seen - p).abs() < 4.0 * sd,
                "cell {c} left out {seen}, expected {p}"
            );
        }
    }
}
