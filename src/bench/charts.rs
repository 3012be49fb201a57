//! The SVG charts of a scene's runs: error and flicker against time on
//! log axes, one line per method sweep.

use super::seeds::{spread, SeedError};
use super::BenchRow;
use anyhow::Result;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// `1234` → "1234", `0.5` → "0.5", `0.0123` → "0.0123": short tick labels.
fn tick(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let digits = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    let s = format!("{v:.digits$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Axis range covering `values` (positive, finite) with a margin on a log
/// scale; a fallback when there are none.
fn log_range(values: impl Iterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite() && *v > 0.0)
        .fold((f64::INFINITY, 0.0_f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return 0.1..10.0;
    }
    // At least a factor of 4 end to end so that a single point has ticks.
    let span = (hi / lo).max(4.0);
    let pad = span.powf(0.12);
    let mid = (hi * lo).sqrt();
    let half = span.sqrt();
    (mid / half / pad)..(mid * half * pad)
}

/// Tick positions of a log axis over `range`: `(labelled, grid only)`.
/// Labelled ticks are 1, 2, 5 × 10^k, or every 1…9 × 10^k when that gives
/// fewer than three; grid lines are the other 1…9 × 10^k.
fn log_ticks(range: &Range<f64>) -> (Vec<f64>, Vec<f64>) {
    let (lo, hi) = (range.start, range.end);
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    let mut all = Vec::new();
    for k in first..=last {
        for m in 1..=9 {
            let v = f64::from(m) * 10f64.powi(k);
            if v >= lo && v <= hi {
                all.push((m, v));
            }
        }
    }
    let main: Vec<f64> = all
        .iter()
        .filter(|(m, _)| [1, 2, 5].contains(m))
        .map(|&(_, v)| v)
        .collect();
    if main.len() >= 3 {
        let grid = all
            .iter()
            .filter(|(m, _)| ![1, 2, 5].contains(m))
            .map(|&(_, v)| v)
            .collect();
        (main, grid)
    } else {
        (all.into_iter().map(|(_, v)| v).collect(), Vec::new())
    }
}

/// The method sweeps of `rows` in order of appearance: (series name, the
/// indices of its rows).
fn series(rows: &[BenchRow]) -> Vec<(String, Vec<usize>)> {
    let several_backends = rows.iter().any(|r| r.backend != rows[0].backend);
    let mut out: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, r) in rows.iter().enumerate() {
        let (key, _) = sweep_of(&r.settings);
        let mut name = if key.is_empty() {
            r.method.clone()
        } else {
            format!("{} ({key})", r.method)
        };
        if several_backends {
            // "cpu" or "gpu": the backend's name up to its details.
            let kind = r.backend.split(" (").next().unwrap_or(&r.backend);
            name = format!("{name} on {kind}");
        }
        match out.iter_mut().find(|(n, _)| *n == name) {
            Some((_, v)) => v.push(i),
            None => out.push((name, vec![i])),
        }
    }
    out
}

/// Short label of a point: the swept value, or nothing for defaults.
fn point_label(r: &BenchRow) -> String {
    sweep_of(&r.settings).1.to_string()
}

/// A run's settings label (`RunSpec::label`) split at its last `=` into
/// what names its series (the fixed settings and the swept key) and the
/// swept value: `at=0.1 max_life=5` → (`at=0.1 max_life`, `5`);
/// `default` → (``, ``).
fn sweep_of(settings: &str) -> (&str, &str) {
    settings.rsplit_once('=').unwrap_or(("", ""))
}

/// The paths of the four charts of `scene` in `out`: error, surface
/// error, flicker, surface flicker.
pub(super) fn chart_paths(out: &Path, scene: &str) -> [PathBuf; 4] {
    ["error", "surface_error", "flicker", "surface_flicker"]
        .map(|what| out.join(format!("{scene}_{what}_vs_time.svg")))
}

/// Writes the four charts of one scene; returns their paths. `seeds`,
/// beside `rows`, holds each run's errors at the seeds it was rendered at
/// (none or one where it was rendered at one): a run of several is drawn
/// at its mean error, as its row gives it, with a bar through it from the
/// least to the greatest of its seeds' errors.
pub fn plot_scene(
    out: &Path,
    scene: &str,
    rows: &[BenchRow],
    seeds: &[Vec<SeedError>],
) -> Result<Vec<PathBuf>> {
    const ONE_FRAME: &str = "flicker needs two frames or more";
    // What each chart (in `chart_paths`' order) draws: its title, its
    // value's name, why it can be empty, and the value of a row and of a
    // seed.
    type Measure = (
        &'static str,
        &'static str,
        &'static str,
        fn(&BenchRow) -> Option<f64>,
        fn(&SeedError) -> Option<f64>,
    );
    let measures: [Measure; 4] = [
        (
            "error against time",
            "relative RMSE against the reference",
            "no run has a finite, positive time and value",
            |r| Some(r.rel_rmse),
            |s| Some(s.rel_rmse),
        ),
        (
            "error of lit surfaces against time",
            "relative RMSE without the pixels at seen lights",
            "the reference has no light masks",
            |r| r.rel_rmse_surfaces,
            |s| s.rel_rmse_surfaces,
        ),
        (
            "flicker against time",
            "flicker (RMS of frame-difference error / mean radiance)",
            ONE_FRAME,
            |r| r.flicker,
            |s| s.flicker,
        ),
        (
            "flicker of lit surfaces against time",
            "flicker without the pixels at seen lights",
            "flicker needs two frames or more, and light masks in the reference",
            |r| r.flicker_surfaces,
            |s| s.flicker_surfaces,
        ),
    ];
    let paths = chart_paths(out, scene);
    for (path, (title, y_desc, empty, of_row, of_seed)) in paths.iter().zip(measures) {
        let bars: Vec<Option<(f64, f64)>> = (0..rows.len())
            .map(|i| seeds.get(i).and_then(|s| spread(s, of_seed)))
            .collect();
        let chart = Chart {
            title: format!("{scene}: {title}"),
            y_desc: y_desc.into(),
            empty,
        };
        plot(path, &chart, rows, of_row, &bars)?;
    }
    Ok(paths.into())
}

/// What one chart shows: its caption, its value's name, and why it can be
/// empty.
struct Chart {
    title: String,
    y_desc: String,
    empty: &'static str,
}

/// A chart of `y_of` against time on log axes, one line per method sweep
/// ([`series`]), written as SVG to `path`; a row with a spread in
/// `spreads` (beside `rows`, or shorter) gets a bar over it.
fn plot(
    path: &Path,
    chart: &Chart,
    rows: &[BenchRow],
    y_of: impl Fn(&BenchRow) -> Option<f64>,
    spreads: &[Option<(f64, f64)>],
) -> Result<()> {
    let Chart {
        title,
        y_desc,
        empty,
    } = chart;
    use plotters::prelude::*;
    let draw_err = |e: &dyn std::fmt::Display| anyhow::anyhow!("drawing {}: {e}", path.display());
    let usable = |r: &&BenchRow| {
        let y = y_of(r);
        r.seconds.is_finite() && r.seconds > 0.0 && y.is_some_and(|y| y.is_finite() && y > 0.0)
    };
    // A bar of a usable row, where its ends are on the axis too.
    let bar_of = |i: usize| {
        let (lo, hi) = spreads.get(i).copied().flatten()?;
        let on_axis = |v: f64| v.is_finite() && v > 0.0;
        (usable(&&rows[i]) && on_axis(lo) && on_axis(hi)).then_some((lo, hi))
    };
    let frames = rows.first().map_or(0, |r| r.frames);
    let x_range = log_range(rows.iter().filter(usable).map(|r| r.seconds));
    let bar_ends = (0..rows.len())
        .filter_map(bar_of)
        .flat_map(|(lo, hi)| [lo, hi]);
    let y_range = log_range(rows.iter().filter(usable).filter_map(&y_of).chain(bar_ends));

    let root = SVGBackend::new(path, (820, 580)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| draw_err(&e))?;
    let mut chart = log_log_chart(&root, title, x_range, y_range).map_err(|e| draw_err(&e))?;
    // Said under the time axis, which has room where the value's axis
    // has none.
    let over_seeds = match (0..rows.len()).any(|i| bar_of(i).is_some()) {
        true => "; a point: the mean over seeds, its bar: their range",
        false => "",
    };
    let x_desc = format!(
        "render time, seconds for {frames} frame{} (log scale){over_seeds}",
        if frames == 1 { "" } else { "s" }
    );
    draw_axes(&mut chart, &x_desc, &format!("{y_desc} (log scale)")).map_err(|e| draw_err(&e))?;

    let mut drawn: Vec<(f64, f64, String)> = Vec::new();
    for (i, (name, sweep)) in series(rows).into_iter().enumerate() {
        let mut points: Vec<(f64, f64, String)> = (sweep.iter())
            .map(|&j| &rows[j])
            .filter(usable)
            .map(|r| (r.seconds, y_of(r).unwrap_or(f64::NAN), point_label(r)))
            .collect();
        if points.is_empty() {
            continue;
        }
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let color = Palette99::pick(i).to_rgba();
        let bars: Vec<(f64, f64, f64)> = (sweep.iter())
            .filter_map(|&j| bar_of(j).map(|(lo, hi)| (rows[j].seconds, lo, hi)))
            .collect();
        draw_bars(&mut chart, color, &bars).map_err(|e| draw_err(&e))?;
        draw_sweep(&mut chart, name, color, &points).map_err(|e| draw_err(&e))?;
        drawn.extend(points);
    }
    draw_point_labels(&mut chart, &drawn).map_err(|e| draw_err(&e))?;
    if !drawn.is_empty() {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| draw_err(&e))?;
    } else {
        root.draw(&Text::new(
            format!("no data: {empty}"),
            (200, 290),
            ("sans-serif", 16),
        ))
        .map_err(|e| draw_err(&e))?;
    }
    if let Some(text) = at_zero_note(rows, &y_of) {
        root.draw(&Text::new(text, (90, 40), ("sans-serif", 13)))
            .map_err(|e| draw_err(&e))?;
    }
    root.present().map_err(|e| draw_err(&e))?;
    Ok(())
}

/// The runs at exactly 0 (no flicker in a static scene), which have no
/// place on a log axis: named in a note on the chart, rather than missing
/// without a word. `None` where there are none.
fn at_zero_note(rows: &[BenchRow], y_of: impl Fn(&BenchRow) -> Option<f64>) -> Option<String> {
    let at_zero: Vec<String> = (rows.iter())
        .filter(|r| r.seconds > 0.0 && y_of(r) == Some(0.0))
        .map(|r| format!("{} {}", r.method, r.settings))
        .collect();
    (!at_zero.is_empty()).then(|| {
        format!(
            "not drawn, at 0 (a log axis has none): {}",
            at_zero.join(", ")
        )
    })
}

/// The grid, ticks and axis names of `chart`.
fn draw_axes(
    chart: &mut LogLogChart,
    x_desc: &str,
    y_desc: &str,
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_label_formatter(&|v| tick(*v))
        .y_label_formatter(&|v| tick(*v))
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 15))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
}

/// The SVG chart area, its axes logarithmic over the ranges, with ticks at
/// 1–2–5 steps ([`log_ticks`]).
type LogLogChart<'a> = plotters::chart::ChartContext<
    'a,
    plotters::backend::SVGBackend<'a>,
    plotters::coord::cartesian::Cartesian2d<
        plotters::coord::combinators::WithKeyPoints<plotters::coord::combinators::LogCoord<f64>>,
        plotters::coord::combinators::WithKeyPoints<plotters::coord::combinators::LogCoord<f64>>,
    >,
>;

/// Builds [`LogLogChart`] on `root` with a caption.
fn log_log_chart<'a>(
    root: &plotters::drawing::DrawingArea<
        plotters::backend::SVGBackend<'a>,
        plotters::coord::Shift,
    >,
    title: &str,
    x_range: std::ops::Range<f64>,
    y_range: std::ops::Range<f64>,
) -> Result<LogLogChart<'a>, plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    let (x_ticks, x_grid) = log_ticks(&x_range);
    let (y_ticks, y_grid) = log_ticks(&y_range);
    ChartBuilder::on(root)
        .caption(title, ("sans-serif", 22))
        .margin(18)
        .x_label_area_size(52)
        .y_label_area_size(78)
        .build_cartesian_2d(
            x_range
                .log_scale()
                .with_key_points(x_ticks)
                .with_light_points(x_grid),
            y_range
                .log_scale()
                .with_key_points(y_ticks)
                .with_light_points(y_grid),
        )
}

/// One method sweep: its points `(seconds, y, label)` joined in time
/// order and each marked, and a legend entry `name` (the labels are
/// [`draw_point_labels`]'s, once every sweep's points are known).
fn draw_sweep(
    chart: &mut LogLogChart,
    name: String,
    color: plotters::style::RGBAColor,
    points: &[(f64, f64, String)],
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    chart
        .draw_series(LineSeries::new(
            points.iter().map(|p| (p.0, p.1)),
            color.stroke_width(2),
        ))?
        .label(name)
        .legend(move |(x, y)| {
            EmptyElement::at((x, y))
                + PathElement::new(vec![(0, 0), (22, 0)], color.stroke_width(2))
                + Circle::new((11, 0), 4, color.filled())
        });
    chart.draw_series((points.iter()).map(|&(x, y, _)| Circle::new((x, y), 4, color.filled())))?;
    Ok(())
}

/// Vertical bars `(seconds, lo, hi)` from `lo` to `hi` at `seconds`, each
/// end capped, thinner than a sweep's line: the spread of a run's error
/// over its seeds.
fn draw_bars(
    chart: &mut LogLogChart,
    color: plotters::style::RGBAColor,
    bars: &[(f64, f64, f64)],
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    let style = color.stroke_width(1);
    let cap =
        move |at: (f64, f64)| EmptyElement::at(at) + PathElement::new(vec![(-5, 0), (5, 0)], style);
    chart.draw_series(
        (bars.iter()).map(|&(x, lo, hi)| PathElement::new(vec![(x, lo), (x, hi)], style)),
    )?;
    chart.draw_series(
        bars.iter()
            .flat_map(|&(x, lo, hi)| [cap((x, lo)), cap((x, hi))]),
    )?;
    Ok(())
}

/// Every sweep's points labelled with their swept values, each label where
/// [`place_labels`] finds room (a default run's point has none: no empty
/// text element for it).
fn draw_point_labels(
    chart: &mut LogLogChart,
    points: &[(f64, f64, String)],
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<std::io::Error>> {
    use plotters::prelude::*;
    let at: Vec<(i32, i32)> = points
        .iter()
        .map(|p| chart.backend_coord(&(p.0, p.1)))
        .collect();
    let labels: Vec<(usize, &str)> = (points.iter().enumerate())
        .filter(|(_, p)| !p.2.is_empty())
        .map(|(i, p)| (i, p.2.as_str()))
        .collect();
    let offsets = place_labels(&at, &labels);
    chart.draw_series(labels.iter().zip(offsets).map(|(&(i, label), offset)| {
        let (x, y, _) = &points[i];
        EmptyElement::at((*x, *y)) + Text::new(label.to_string(), offset, ("sans-serif", 13))
    }))?;
    Ok(())
}

/// Height of a point label in pixels (13-pixel sans-serif) and the width
/// of one of its characters, about: digits are 0.56 em wide in the usual
/// sans-serif faces.
const LABEL_HEIGHT: i32 = 13;
const LABEL_CHAR_WIDTH: i32 = 8;

/// A box in pixels: left, top, right, bottom.
type PixelBox = [i32; 4];

fn overlaps(a: &PixelBox, b: &PixelBox) -> bool {
    a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3]
}

/// Where each label goes, as the offset of its top-left corner from its
/// point (`labels`: the index of the point in `points`, pixel positions,
/// and the text). A label takes the first place around its point, in a
/// fixed order (above right first), that covers no label placed before it
/// and no point's marker; where none is free, the first place. Points of
/// two sweeps close in time and error (`trc` and `tcg` among the moving
/// balls) printed their values over each other with one place for all.
fn place_labels(points: &[(i32, i32)], labels: &[(usize, &str)]) -> Vec<(i32, i32)> {
    let markers: Vec<PixelBox> = (points.iter())
        .map(|&(x, y)| [x - 5, y - 5, x + 5, y + 5])
        .collect();
    let mut placed: Vec<PixelBox> = Vec::with_capacity(labels.len());
    let mut offsets = Vec::with_capacity(labels.len());
    for &(i, text) in labels {
        let (x, y) = points[i];
        let width = LABEL_CHAR_WIDTH * text.chars().count() as i32;
        let places = [
            (6, -16),
            (6, 4),
            (-6 - width, -16),
            (-6 - width, 4),
            (-width / 2, -22),
            (-width / 2, 9),
        ];
        let boxed = |(dx, dy): (i32, i32)| [x + dx, y + dy, x + dx + width, y + dy + LABEL_HEIGHT];
        let free = |&place: &(i32, i32)| {
            let b = boxed(place);
            !placed
                .iter()
                .chain(&markers)
                .any(|other| overlaps(&b, other))
        };
        let place = places.iter().copied().find(free).unwrap_or(places[0]);
        placed.push(boxed(place));
        offsets.push(place);
    }
    offsets
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_short() {
        assert_eq!(tick(1234.0), "1234");
        assert_eq!(tick(0.5), "0.5");
        assert_eq!(tick(2.0), "2");
        assert_eq!(tick(0.0123), "0.0123");
        assert_eq!(tick(0.2), "0.2");
    }

    #[test]
    fn log_ticks_label_an_axis_within_a_decade() {
        let (main, _) = log_ticks(&(1.3..4.6));
        assert_eq!(main, [2.0, 3.0, 4.0]);
        let (main, grid) = log_ticks(&(0.05..30.0));
        assert_eq!(main, [0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0]);
        assert!(grid.contains(&3.0) && !grid.contains(&2.0));
    }

    #[test]
    fn runs_of_one_sweep_share_a_series() {
        assert_eq!(sweep_of("spp=16"), ("spp", "16"));
        assert_eq!(sweep_of("at=0.1 max_life=5"), ("at=0.1 max_life", "5"));
        assert_eq!(
            sweep_of("at=0.1 max_life=20").0,
            sweep_of("at=0.1 max_life=5").0
        );
        assert_ne!(
            sweep_of("at=0.2 max_life=5").0,
            sweep_of("at=0.1 max_life=5").0
        );
        assert_eq!(sweep_of("default"), ("", ""));
    }

    #[test]
    fn labels_of_points_close_together_do_not_overlap() {
        // Two sweeps' points 10 pixels apart, as `trc`'s and `tcg`'s
        // among the moving balls, and one far away.
        let points = [(300, 200), (310, 200), (600, 400)];
        let labels = [(0, "0.2"), (1, "20"), (2, "5")];
        let offsets = place_labels(&points, &labels);
        let boxes: Vec<PixelBox> = (labels.iter().zip(&offsets))
            .map(|(&(i, text), &(dx, dy))| {
                let (x, y) = (points[i].0 + dx, points[i].1 + dy);
                let width = LABEL_CHAR_WIDTH * text.len() as i32;
                [x, y, x + width, y + LABEL_HEIGHT]
            })
            .collect();
        assert!(!overlaps(&boxes[0], &boxes[1]), "{boxes:?}");
        for (b, &(x, y)) in boxes.iter().zip(&points) {
            for &(px, py) in &points {
                assert!(
                    !overlaps(b, &[px - 5, py - 5, px + 5, py + 5]),
                    "{b:?} at ({x}, {y})"
                );
            }
        }
        // A lone point keeps the usual place, above right.
        assert_eq!(offsets[2], (6, -16));
    }

    #[test]
    fn log_range_covers_points() {
        let r = log_range([0.5, 8.0].into_iter());
        assert!(r.start < 0.5 && r.end > 8.0);
        let one = log_range([3.0].into_iter());
        assert!(one.start < 3.0 && one.end > 3.0 && one.end / one.start >= 4.0);
        assert_eq!(log_range(std::iter::empty()), 0.1..10.0);
    }
}
