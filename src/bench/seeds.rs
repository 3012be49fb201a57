//! A run's errors at each seed it was rendered at
//! ([`super::BenchOptions::seeds`]): the lines printed under the tables,
//! `bench_seeds.csv` beside `bench.csv` (one line per run and seed, which
//! `--replot` reads back), and the spread the error chart draws as a bar
//! through each run's mean.

use super::report::{csv_lines, run_fields};
use super::BenchRow;
use anyhow::{anyhow, bail, Result};
use std::fmt::Write as _;

/// A run's errors at one seed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeedError {
    pub seed: u64,
    pub rel_rmse: f64,
    pub block_bias: f64,
}

/// The name of the file beside `bench.csv` that keeps each seed's errors.
pub const SEEDS_CSV: &str = "bench_seeds.csv";

/// [`SEEDS_CSV`]'s header line: a run is named by its first four fields,
/// as in `bench.csv`.
pub const SEEDS_CSV_HEADER: &str = "scene,method,settings,backend,seed,rel_rmse,block_bias";

/// The least and greatest relative RMSE over a run's seeds; `None` for a
/// run of one seed (nothing to spread).
pub fn spread(seeds: &[SeedError]) -> Option<(f64, f64)> {
    if seeds.len() < 2 {
        return None;
    }
    let errors = seeds.iter().map(|s| s.rel_rmse);
    let lo = errors.clone().fold(f64::INFINITY, f64::min);
    let hi = errors.fold(f64::NEG_INFINITY, f64::max);
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
                "{},{},{:.6},{:.6}",
                run_fields(r),
                s.seed,
                s.rel_rmse,
                s.block_bias,
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
    let error = |i: usize| -> Result<f64> {
        match fields[i].trim().parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ => bail!("{} is not a number: '{}'", columns[i], fields[i]),
        }
    };
    let seed = SeedError {
        seed,
        rel_rmse: error(5)?,
        block_bias: error(6)?,
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
            block_bias: rel_rmse / 10.0,
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
        let bad = text.replace("0.062500", "x");
        let e = seeds_from_csv(&bad, &rows).unwrap_err();
        assert!(
            format!("{e}").contains("line 3: rel_rmse is not a number: 'x'"),
            "{e}"
        );
        let e = seeds_from_csv("scene,seed\n", &rows).unwrap_err();
        assert!(format!("{e}").contains("line 1"), "{e}");
    }

    #[test]
    fn the_spread_is_the_least_and_greatest_error() {
        assert_eq!(spread(&[at(0, 0.2)]), None);
        assert_eq!(
            spread(&[at(0, 0.2), at(1, 0.1), at(2, 0.4)]),
            Some((0.1, 0.4))
        );
    }
}
