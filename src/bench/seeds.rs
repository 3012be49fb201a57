//! A run's errors at each seed it was rendered at
//! ([`super::BenchOptions::seeds`]): the lines printed under the tables,
//! `bench_seeds.csv` beside `bench.csv` (one line per run and seed, which
//! `--replot` reads back), and the spread the charts draw as a bar
//! through each run's mean.

use super::report::{csv_lines, opt, run_fields};
use super::BenchRow;
use crate::metrics::CompareReport;
use anyhow::{anyhow, bail, Result};
use std::fmt::Write as _;

/// A run's errors at one seed: those of [`BenchRow`] that a comparison
/// with the reference gives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeedError {
    pub seed: u64,
    pub rel_rmse: f64,
    pub rel_rmse_surfaces: Option<f64>,
    pub block_bias: f64,
    pub flicker: Option<f64>,
    pub flicker_surfaces: Option<f64>,
}

impl SeedError {
    /// The errors of `row`, rendered at `seed`.
    pub fn of_row(seed: u64, row: &BenchRow) -> Self {
        SeedError {
            seed,
            rel_rmse: row.rel_rmse,
            rel_rmse_surfaces: row.rel_rmse_surfaces,
            block_bias: row.block_bias,
            flicker: row.flicker,
            flicker_surfaces: row.flicker_surfaces,
        }
    }

    /// The errors `compared` gives of a run rendered at `seed`.
    pub fn of_comparison(seed: u64, compared: &CompareReport) -> Self {
        SeedError {
            seed,
            rel_rmse: compared.rel_rmse,
            rel_rmse_surfaces: compared.rel_rmse_surfaces,
            block_bias: compared.block_bias,
            flicker: compared.flicker,
            flicker_surfaces: compared.flicker_surfaces,
        }
    }

    /// Sets `row`'s errors to their means over `seeds` (one at least): an
    /// error that some seed lacks (flicker of one frame) stays absent.
    pub fn means_into(seeds: &[SeedError], row: &mut BenchRow) {
        let n = seeds.len() as f64;
        let mean = |each: fn(&SeedError) -> f64| seeds.iter().map(each).sum::<f64>() / n;
        let mean_of = |each: fn(&SeedError) -> Option<f64>| {
            let all: Option<Vec<f64>> = seeds.iter().map(each).collect();
            Some(all?.iter().sum::<f64>() / n)
        };
        row.rel_rmse = mean(|s| s.rel_rmse);
        row.rel_rmse_surfaces = mean_of(|s| s.rel_rmse_surfaces);
        row.block_bias = mean(|s| s.block_bias);
        row.flicker = mean_of(|s| s.flicker);
        row.flicker_surfaces = mean_of(|s| s.flicker_surfaces);
    }
}

/// The name of the file beside `bench.csv` that keeps each seed's errors.
pub const SEEDS_CSV: &str = "bench_seeds.csv";

/// [`SEEDS_CSV`]'s header line: a run is named by its first four fields,
/// as in `bench.csv`.
pub const SEEDS_CSV_HEADER: &str =
    "scene,method,settings,backend,seed,rel_rmse,rel_rmse_surfaces,block_bias,flicker,flicker_surfaces";

/// The least and greatest of an error (`error_of`) over a run's seeds;
/// `None` for a run of one seed (nothing to spread) or where a seed lacks
/// it.
pub fn spread(seeds: &[SeedError], error_of: fn(&SeedError) -> Option<f64>) -> Option<(f64, f64)> {
    if seeds.len() < 2 {
        return None;
    }
    let errors: Vec<f64> = seeds.iter().map(error_of).collect::<Option<_>>()?;
    let lo = errors.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = errors.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    Some((lo, hi))
}

/// The text of [`SEEDS_CSV`]: its header and a line per run and seed, in
/// the rows' order and each run's seed order.
pub fn seeds_to_csv(rows: &[BenchRow], seeds: &[Vec<SeedError>]) -> String {
    let mut out = format!("{SEEDS_CSV_HEADER}\n");
    for (r, seeds) in rows.iter().zip(seeds) {
        for s in seeds {
            let _ = writeln!(
                out,
                "{},{},{:.6},{},{:.6},{},{}",
                run_fields(r),
                s.seed,
                s.rel_rmse,
                opt(s.rel_rmse_surfaces, 6),
                s.block_bias,
                opt(s.flicker, 6),
                opt(s.flicker_surfaces, 6),
            );
        }
    }
    out
}

/// Each of `rows`' seed errors from the text of a [`SEEDS_CSV`]
/// ([`seeds_to_csv`]'s), for `--replot`: a line belongs to the row of
/// `bench.csv` its first four fields name. A line naming no row, or a
/// run that `bench.csv` holds twice (merged from two benches: which one
/// it was is unknown), is an error naming its line, as is a field that
/// does not read.
pub fn seeds_from_csv(text: &str, rows: &[BenchRow]) -> Result<Vec<Vec<SeedError>>> {
    let mut seeds = vec![Vec::new(); rows.len()];
    for (line, fields) in csv_lines(text, SEEDS_CSV_HEADER)? {
        let (row, seed) = seed_line(&fields, rows).map_err(|e| anyhow!("line {line}: {e}"))?;
        seeds[row].push(seed);
    }
    Ok(seeds)
}

/// One line of a [`SEEDS_CSV`]: the index of its run in `rows`, and its
/// errors.
fn seed_line(fields: &[String], rows: &[BenchRow]) -> Result<(usize, SeedError)> {
    let columns: Vec<&str> = SEEDS_CSV_HEADER.split(',').collect();
    if fields.len() != columns.len() {
        bail!("{} fields, the header has {}", fields.len(), columns.len());
    }
    let named = |r: &BenchRow| [&*r.scene, &r.method, &r.settings, &r.backend] == fields[..4];
    let mut of_run = rows.iter().enumerate().filter(|(_, r)| named(r));
    let run = fields[..4].join(" ");
    let Some((row, _)) = of_run.next() else {
        bail!("no run '{run}' in bench.csv");
    };
    if of_run.next().is_some() {
        bail!("bench.csv holds the run '{run}' twice: which one this seed is of is unknown");
    }
    let seed = fields[4]
        .trim()
        .parse()
        .map_err(|_| anyhow!("seed is not a whole number: '{}'", fields[4]))?;
    // An error not measured (flicker of one frame) is an empty field.
    let error_if_any = |i: usize| -> Result<Option<f64>> {
        let f = fields[i].trim();
        match f.parse::<f64>() {
            _ if f.is_empty() => Ok(None),
            Ok(v) if v.is_finite() => Ok(Some(v)),
            _ => bail!("{} is not a number: '{}'", columns[i], fields[i]),
        }
    };
    let error = |i: usize| error_if_any(i)?.ok_or_else(|| anyhow!("{} is empty", columns[i]));
    let seed = SeedError {
        seed,
        rel_rmse: error(5)?,
        rel_rmse_surfaces: error_if_any(6)?,
        block_bias: error(7)?,
        flicker: error_if_any(8)?,
        flicker_surfaces: error_if_any(9)?,
    };
    Ok((row, seed))
}

/// Lines for people where the runs were rendered at several seeds: one
/// per row, its relative RMSE and block bias at each seed, in order, and
/// the means the tables give. Empty for one seed.
pub fn seeds_text(rows: &[BenchRow], seeds: &[Vec<SeedError>]) -> String {
    let mut out = String::new();
    if seeds.iter().all(|s| s.len() <= 1) {
        return out;
    }
    for (row, seeds) in rows.iter().zip(seeds) {
        let each = |f: fn(&SeedError) -> f64| {
            let all: Vec<String> = seeds.iter().map(|s| format!("{:.5}", f(s))).collect();
            all.join(" / ")
        };
        let _ = writeln!(
            out,
            "{} {} {} on {}, seeds {}: rel_rmse {} → {:.5}; block_bias {} → {:.5}",
            row.scene,
            row.method,
            row.settings,
            row.backend,
            seeds
                .iter()
                .map(|s| s.seed.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            each(|s| s.rel_rmse),
            row.rel_rmse,
            each(|s| s.block_bias),
            row.block_bias,
        );
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(settings: &str) -> BenchRow {
        let csv = format!(
            "{}\ns,trc,{settings},\"cpu (2 threads)\",4,1.5,,10,20,,0.1,,0.01,,,,,,,,,,\n",
            super::super::CSV_HEADER
        );
        super::super::from_csv(&csv).unwrap().remove(0)
    }

    fn at(seed: u64, rel_rmse: f64) -> SeedError {
        SeedError {
            seed,
            rel_rmse,
            rel_rmse_surfaces: Some(rel_rmse / 2.0),
            block_bias: rel_rmse / 10.0,
            flicker: (seed > 0).then_some(rel_rmse * 4.0),
            flicker_surfaces: None,
        }
    }

    #[test]
    fn seed_errors_read_back_into_the_runs_that_wrote_them() {
        let rows = [row("max_life=2"), row("max_life=20")];
        let seeds = vec![
            vec![at(0, 0.125), at(1, 0.0625)],
            vec![at(0, 0.25), at(1, 0.5), at(2, 0.375)],
        ];
        let text = seeds_to_csv(&rows, &seeds);
        assert_eq!(seeds_from_csv(&text, &rows).unwrap(), seeds);
        // A run of bench.csv that the file names no seed of has none.
        let fewer = seeds_to_csv(&rows[1..], &seeds[1..]);
        assert_eq!(
            seeds_from_csv(&fewer, &rows).unwrap(),
            [Vec::new(), seeds[1].clone()]
        );
    }

    #[test]
    fn a_seed_line_of_no_run_or_of_an_ambiguous_run_is_refused() {
        let rows = [row("max_life=2")];
        let seeds = vec![vec![at(0, 0.125), at(1, 0.0625)]];
        let text = seeds_to_csv(&rows, &seeds);
        let e = seeds_from_csv(&text, &[row("max_life=5")]).unwrap_err();
        assert!(
            format!("{e}").contains("line 2: no run 's trc max_life=2"),
            "{e}"
        );
        let e = seeds_from_csv(&text, &[row("max_life=2"), row("max_life=2")]).unwrap_err();
        assert!(format!("{e}").contains("twice"), "{e}");
        let bad = text.replace("0.012500", "x");
        let e = seeds_from_csv(&bad, &rows).unwrap_err();
        assert!(
            format!("{e}").contains("line 2: block_bias is not a number: 'x'"),
            "{e}"
        );
        let e = seeds_from_csv("scene,seed\n", &rows).unwrap_err();
        assert!(format!("{e}").contains("line 1"), "{e}");
    }

    #[test]
    fn the_spread_is_the_least_and_greatest_error() {
        let rel_rmse = |s: &SeedError| Some(s.rel_rmse);
        assert_eq!(spread(&[at(0, 0.2)], rel_rmse), None);
        let three = [at(0, 0.2), at(1, 0.1), at(2, 0.4)];
        assert_eq!(spread(&three, rel_rmse), Some((0.1, 0.4)));
        assert_eq!(spread(&three, |s| s.rel_rmse_surfaces), Some((0.05, 0.2)));
        // Seed 0 has no flicker: no spread of it.
        assert_eq!(spread(&three, |s| s.flicker), None);
        assert_eq!(spread(&three[1..], |s| s.flicker), Some((0.4, 1.6)));
    }

    #[test]
    fn a_rows_errors_become_the_means_over_its_seeds() {
        let mut r = row("default");
        SeedError::means_into(&[at(1, 0.1), at(2, 0.4)], &mut r);
        assert!((r.rel_rmse - 0.25).abs() < 1e-15);
        assert!((r.rel_rmse_surfaces.unwrap() - 0.125).abs() < 1e-15);
        assert!((r.block_bias - 0.025).abs() < 1e-15);
        assert!((r.flicker.unwrap() - 1.0).abs() < 1e-15);
        assert_eq!(r.flicker_surfaces, None);
        // Where one seed lacks an error, the mean does too.
        SeedError::means_into(&[at(0, 0.1), at(2, 0.4)], &mut r);
        assert_eq!(r.flicker, None);
        assert_eq!(SeedError::of_row(7, &r).seed, 7);
        assert_eq!(SeedError::of_row(7, &r).rel_rmse, r.rel_rmse);
    }
}
