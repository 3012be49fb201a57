//! Methods by name and their settings by name-value pairs: what
//! `radcache bench --methods trc:max_life=2,5,20` and the `settings` of a
//! job request (`POST /api/jobs`) are turned into, with one error type
//! that names what is known; and the range of every setting ([`limits`]),
//! which `radcache render`'s flags take too.

use crate::cache::gather::Strata;
use crate::method::ic::{GlossyLobe, IcSettings};
use crate::method::movies::MoviesSettings;
use crate::method::path::PathSettings;
use crate::method::tcg::TcgSettings;
use crate::method::trc::{NextDirect, TemporalGradients, TrcSettings};
use crate::render::MethodSettings;
use std::fmt::Display;
use std::str::FromStr;

/// The values a number setting may take, both ends included. Each
/// setting's are in [`limits`], the one place they are set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits<T> {
    pub min: T,
    pub max: T,
}

impl<T: FromStr + PartialOrd + Display + Copy> Limits<T> {
    /// `text` as a `T` within the limits; else what was expected
    /// ("expected a number from 1 to 64", the same words whether `text` is
    /// out of the range or no number of the kind), for the caller to say
    /// whose value it was.
    pub fn parse(&self, text: &str) -> Result<T, String> {
        let expected = || format!("expected a number from {} to {}", self.min, self.max);
        let v: T = text.parse().map_err(|_| expected())?;
        // Written so that NaN is outside.
        if self.min <= v && v <= self.max {
            Ok(v)
        } else {
            Err(expected())
        }
    }

    /// [`Self::parse`] as a clap value parser: a flag's error then names
    /// the flag, the value and the range.
    pub fn parser(self) -> impl Fn(&str) -> Result<T, String> + Clone + Send + Sync + 'static
    where
        T: Send + Sync + 'static,
    {
        move |text: &str| self.parse(text)
    }
}

/// The range of every number setting: **the one place it is set**. The
/// names ([`method_settings`]: `radcache bench --methods`, `POST
/// /api/jobs`) and `radcache render`'s flags (`cli::args`) both check
/// their values against these, so that every value a flag takes can be
/// posted back by its name (the server has work limits of its own on top:
/// `server::request`).
pub mod limits {
    use super::Limits;
    use crate::method::movies::MAX_SHADOW_SAMPLES;

    /// Samples per pixel (`spp`, `--spp`; for `ic`, `trc` and `tcg` those
    /// of direct light and anti-aliasing).
    pub const SPP: Limits<u32> = Limits {
        min: 1,
        max: 1_000_000,
    };
    /// Bounces of a pixel's paths (`max_depth`, `--max-depth`) and the
    /// bounce where Russian roulette starts (`rr_start`): Russian roulette
    /// ends paths long before 10,000 bounces, so a larger bound is a typo.
    pub const PATH_DEPTH: Limits<u32> = Limits {
        min: 0,
        max: 10_000,
    };
    /// Accuracy `a` of the irradiance cache (`accuracy`, `--ic-accuracy`):
    /// Ward 1988 recommends 0.1–0.3; below 0.001 nearly every pixel is a
    /// record of its own, and past 2 records reach past anything they saw.
    pub const ACCURACY: Limits<f32> = Limits {
        min: 0.001,
        max: 2.0,
    };
    /// Record spacing in pixels (`min_spacing`, `max_spacing`,
    /// `--ic-min-spacing`, `--ic-max-spacing`): 10⁶ pixels is past any
    /// image (`render` takes sides up to 16384).
    pub const SPACING_PX: Limits<f32> = Limits {
        min: 0.001,
        max: 1e6,
    };
    /// EAS precision τ (`eas_tau`, `--ic-eas-tau`; the paper uses 0.02).
    pub const EAS_TAU: Limits<f32> = Limits {
        min: 1e-6,
        max: 1e6,
    };
    /// `trc`'s temporal accuracy `a_t` (`at`, `--trc-at`; the paper uses
    /// 0.05, and 100000 is how the bench turns the temporal weight off).
    pub const TEMPORAL_ACCURACY: Limits<f32> = Limits {
        min: 1e-6,
        max: 1e6,
    };
    /// `trc`'s δt_max in frames (`max_life`, `--trc-max-life`).
    pub const MAX_LIFE: Limits<u32> = Limits {
        min: 1,
        max: 100_000,
    };
    /// A share of `tcg`'s Eq. 2 (`tau_min`, `tau_max`, `--tcg-tau-min`,
    /// `--tcg-tau-max`).
    pub const SHARE: Limits<f32> = Limits { min: 0.0, max: 1.0 };
    /// `tcg`'s §4.2 neighbour bound (`max_neighbours`,
    /// `--tcg-max-neighbours`).
    pub const MAX_NEIGHBOURS: Limits<u32> = Limits {
        min: 0,
        max: 1_000_000,
    };
    /// `movies`' shadow samples per texel (`shadow_samples`,
    /// `--movies-shadow-samples`): what the direct pass holds per texel.
    pub const SHADOW_SAMPLES: Limits<u32> = Limits {
        min: 1,
        max: MAX_SHADOW_SAMPLES,
    };
    /// `movies`' texels across a pixel (`texels_per_pixel`,
    /// `--movies-texels-per-pixel`): past 16 a frame's movies take minutes
    /// and gigabytes.
    pub const TEXELS_PER_PIXEL: Limits<f32> = Limits {
        min: 0.01,
        max: 16.0,
    };
    /// `movies`' finest texture, texels along an edge (`max_resolution`,
    /// `--movies-max-resolution`).
    pub const MAX_RESOLUTION: Limits<u32> = Limits { min: 1, max: 1024 };
    /// `movies`' memory for kept static shadows in MiB (`memory_mib`,
    /// `--movies-memory-mib`): up to 1 TiB.
    pub const MEMORY_MIB: Limits<u32> = Limits {
        min: 0,
        max: 1_048_576,
    };
    /// `movies`' global-pass grid spacing, a fraction of the static
    /// scene's diagonal, or of what its camera sees, at films up to 128
    /// pixels high (finer past that: `view::film_share`)
    /// (`global::meshing_size`; `spacing`, `--movies-spacing`). At 1 every static
    /// triangle is one cell already; below 0.001 the pass would coarsen
    /// the grid anyway to keep its links within `mesh::MAX_LINKS`.
    pub const GRID_SPACING: Limits<f32> = Limits {
        min: 0.001,
        max: 1.0,
    };
    /// `movies`' global-pass links of a vertex (`links`, `--movies-links`).
    pub const LINKS: Limits<u32> = Limits { min: 1, max: 1024 };
    /// `movies`' global-pass bounces (`bounces`, `--movies-bounces`).
    pub const BOUNCES: Limits<u32> = Limits { min: 0, max: 64 };
    /// Most gather rays, and hemisphere cells, of a record (`strata`
    /// M × N, `--ic-strata`): 64 × 64, the paper's hemisphere (TRC §6),
    /// times 16. A record keeps a sample of 8 bytes a cell (`tcg` keeps
    /// them in memory across frames, and the store keeps them all), so a
    /// record holds at most 512 KiB; each side may be anything from 1 that
    /// keeps the product within this.
    pub const MAX_GATHER_RAYS: u32 = 65_536;
}

/// `text` as `MxN` hemisphere cells of a record (`strata`, `--ic-strata`):
/// plain decimal sides of at least 1, at most [`limits::MAX_GATHER_RAYS`]
/// cells in all.
pub fn parse_strata(text: &str) -> Result<Strata, String> {
    let not_mxn = || format!("'{text}' is not MxN, e.g. 16x48");
    let (m, n) = text.split_once('x').ok_or_else(not_mxn)?;
    // Plain decimal sides of at least 1 (`str::parse` would take a `+`).
    let side = |v: &str| {
        let digits = !v.is_empty() && v.bytes().all(|b| b.is_ascii_digit());
        let v = digits.then(|| v.parse::<u32>().ok()).flatten();
        v.filter(|&v| v > 0).ok_or_else(not_mxn)
    };
    let (m, n) = (side(m)?, side(n)?);
    let max = limits::MAX_GATHER_RAYS;
    if u64::from(m) * u64::from(n) > u64::from(max) {
        return Err(format!(
            "{m}x{n} cells per record is too many (at most {max})"
        ));
    }
    Ok(Strata { theta: m, phi: n })
}

/// A method by name, and the settings its name-value pairs may change.
pub struct MethodInfo {
    pub name: &'static str,
    /// `(key, example value)`: every key [`method_settings`] accepts for
    /// this method, with a value it accepts (checked by a unit test).
    pub keys: &'static [(&'static str, &'static str)],
}

/// Every method `radcache bench --methods` and `POST /api/jobs` accept.
/// Keep in step with [`method_settings`].
pub const METHODS: &[MethodInfo] = &[
    MethodInfo {
        name: "path",
        keys: &[("spp", "16"), ("max_depth", "8"), ("rr_start", "3")],
    },
    MethodInfo {
        name: "ic",
        keys: &[
            ("accuracy", "0.2"),
            ("spp", "4"),
            ("strata", "16x48"),
            ("min_spacing", "2"),
            ("max_spacing", "64"),
            ("gradients", "1"),
            ("max_depth", "8"),
            ("glossy", "eas"),
            ("eas_tau", "0.02"),
        ],
    },
    MethodInfo {
        name: "trc",
        keys: &[
            ("at", "0.05"),
            ("max_life", "20"),
            ("gradients", "extrapolated"),
            ("reprojection", "1"),
            ("next_direct", "long-lives"),
            ("keep_paths", "0"),
            ("history", "0"),
            ("spatial_gradients", "0"),
            ("spp", "4"),
            ("accuracy", "0.2"),
            ("strata", "16x48"),
            ("min_spacing", "2"),
            ("max_spacing", "64"),
            ("max_depth", "8"),
            ("glossy", "eas"),
            ("eas_tau", "0.02"),
        ],
    },
    MethodInfo {
        name: "tcg",
        keys: &[
            ("tau_min", "0.05"),
            ("tau_max", "1"),
            ("max_neighbours", "10"),
            ("light_refresh", "0"),
            ("occlusion_refresh", "1"),
            ("arrivals", "0"),
            ("spp", "4"),
            ("accuracy", "0.2"),
            ("strata", "16x48"),
            ("min_spacing", "2"),
            ("max_spacing", "64"),
            ("gradients", "1"),
            ("max_depth", "8"),
            ("glossy", "eas"),
            ("eas_tau", "0.02"),
        ],
    },
    MethodInfo {
        name: "movies",
        keys: &[
            ("spp", "16"),
            ("shadow_samples", "16"),
            ("texels_per_pixel", "1"),
            ("max_resolution", "256"),
            ("memory_mib", "512"),
            ("spacing", "0.03125"),
            ("links", "128"),
            ("bounces", "64"),
            ("max_depth", "8"),
        ],
    },
];

/// Errors of method specifications; each names what is known.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MethodError {
    #[error("unknown method '{name}'; known methods: {known}")]
    UnknownMethod { name: String, known: String },
    #[error("method '{method}' has no setting '{key}'; its settings: {known}")]
    UnknownKey {
        method: String,
        key: String,
        known: String,
    },
    #[error("{method}: bad value '{value}' for {key}: {problem}")]
    BadValue {
        method: String,
        key: String,
        value: String,
        problem: String,
    },
    #[error("{method}: {problem}")]
    Inconsistent { method: String, problem: String },
    #[error("bad method specification '{spec}': {problem} (expected NAME, NAME:KEY=V1,V2,… or NAME:KEY=V:KEY=V1,V2,…, at most one setting with several values, e.g. path:spp=4,16,64 or trc:at=0.1:max_life=2,5)")]
    BadSpec { spec: String, problem: String },
}

fn known_methods() -> String {
    METHODS
        .iter()
        .map(|m| m.name)
        .collect::<Vec<_>>()
        .join(", ")
}

fn known_keys(method: &str) -> String {
    METHODS
        .iter()
        .find(|m| m.name == method)
        .map(|m| {
            m.keys
                .iter()
                .map(|(k, _)| *k)
                .collect::<Vec<_>>()
                .join(", ")
        })
        .unwrap_or_default()
}

/// Parses `value` of setting `key` of `method` as a `T` within `range`.
fn value<T>(method: &str, key: &str, value: &str, range: Limits<T>) -> Result<T, MethodError>
where
    T: FromStr + PartialOrd + Display + Copy,
{
    range
        .parse(value.trim())
        .map_err(|problem| MethodError::BadValue {
            method: method.into(),
            key: key.into(),
            value: value.into(),
            problem,
        })
}

/// Parses the path length `max_depth`: a number of bounces, or
/// [`UNBOUNDED`] (Russian roulette alone ends paths, the default).
fn depth(method: &str, key: &str, v: &str) -> Result<Option<u32>, MethodError> {
    match v.trim() {
        UNBOUNDED => Ok(None),
        v => limits::PATH_DEPTH
            .parse(v)
            .map(Some)
            .map_err(|problem| MethodError::BadValue {
                method: method.into(),
                key: key.into(),
                value: v.into(),
                problem: format!("{problem}, or {UNBOUNDED} (unbounded)"),
            }),
    }
}

/// The value of `max_depth` that leaves paths unbounded.
pub const UNBOUNDED: &str = "none";

/// Parses the on/off setting `key` of `method`: `1`, `on` or `true`, or
/// `0`, `off` or `false` (as the CLI's flags and JSON's booleans give it).
fn flag(method: &str, key: &str, v: &str) -> Result<bool, MethodError> {
    match v.trim() {
        "1" | "on" | "true" => Ok(true),
        "0" | "off" | "false" => Ok(false),
        _ => Err(MethodError::BadValue {
            method: method.into(),
            key: key.into(),
            value: v.into(),
            problem: "expected 1, on or true, or 0, off or false".into(),
        }),
    }
}

/// Applies `ic`'s setting `key = v` to `s` (also for `trc`, whose records
/// are `ic`'s); `false` when `key` is none of them.
fn ic_setting(method: &str, key: &str, v: &str, s: &mut IcSettings) -> Result<bool, MethodError> {
    match key {
        "accuracy" => s.accuracy = value(method, key, v, limits::ACCURACY)?,
        "spp" => s.spp = value(method, key, v, limits::SPP)?,
        "strata" => {
            s.strata = parse_strata(v.trim()).map_err(|problem| MethodError::BadValue {
                method: method.into(),
                key: key.into(),
                value: v.into(),
                problem,
            })?
        }
        "min_spacing" => s.min_spacing_px = value(method, key, v, limits::SPACING_PX)?,
        "max_spacing" => s.max_spacing_px = value(method, key, v, limits::SPACING_PX)?,
        "gradients" => s.gradients = flag(method, key, v)?,
        // The pixel paths' (`render --max-depth`), not the gathers'.
        "max_depth" => s.length.max_depth = depth(method, key, v)?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// The settings of `method` with its defaults (the papers', as
/// `radcache render` has them), and each `(key, value)` of `changes`
/// applied in order. **The one place that maps names to
/// [`MethodSettings`]**: a new method adds an arm here and in `apply`,
/// and a row to [`METHODS`].
pub fn method_settings<'a>(
    method: &str,
    changes: impl IntoIterator<Item = (&'a str, &'a str)>,
) -> Result<MethodSettings, MethodError> {
    let mut settings = match method {
        "path" => MethodSettings::Path(PathSettings::default()),
        "ic" => MethodSettings::Ic(IcSettings::default()),
        "trc" => MethodSettings::Trc(TrcSettings::default()),
        "tcg" => MethodSettings::Tcg(TcgSettings::default()),
        "movies" => MethodSettings::Movies(MoviesSettings::default()),
        _ => {
            return Err(MethodError::UnknownMethod {
                name: method.into(),
                known: known_methods(),
            })
        }
    };
    for (key, v) in changes {
        apply(&mut settings, key, v)?;
    }
    check_consistent(&settings)?;
    Ok(settings)
}

/// Settings each within its range that contradict each other: a minimum
/// over its maximum (the method would quietly take one of them).
pub fn check_consistent(settings: &MethodSettings) -> Result<(), MethodError> {
    let ic = match settings {
        MethodSettings::Ic(ic) => Some(ic),
        MethodSettings::Trc(trc) => Some(&trc.ic),
        MethodSettings::Tcg(tcg) => Some(&tcg.ic),
        MethodSettings::Path(_) | MethodSettings::Movies(_) => None,
    };
    let inconsistent = |problem: String| MethodError::Inconsistent {
        method: settings.name().into(),
        problem,
    };
    if let Some(ic) = ic.filter(|ic| ic.min_spacing_px > ic.max_spacing_px) {
        return Err(inconsistent(format!(
            "min_spacing {} is over max_spacing {}",
            ic.min_spacing_px, ic.max_spacing_px
        )));
    }
    if let MethodSettings::Tcg(tcg) = settings {
        if tcg.tau_min > tcg.tau_max {
            return Err(inconsistent(format!(
                "tau_min {} is over tau_max {}",
                tcg.tau_min, tcg.tau_max
            )));
        }
    }
    Ok(())
}

/// `settings` as their serde JSON without the enum's tag (the method's
/// name): every setting, as the store's settings identity holds it. Through
/// the text, not `to_value`: that widens an `f32` 0.3 to
/// 0.30000001192092896.
pub fn settings_json(settings: &MethodSettings) -> serde_json::Value {
    serde_json::to_string(settings)
        .and_then(|text| serde_json::from_str(&text))
        .map_or(serde_json::Value::Null, untagged)
}

/// Every setting of `settings` that a name sets, by that name (as
/// [`method_settings`] and `POST /api/jobs` take them), with its value:
/// numbers as numbers, flags as booleans, the rest as their text. Given
/// back to [`method_settings`] they make the same settings. A path length
/// left unbounded is `max_depth` "none" ([`UNBOUNDED`]).
pub fn named_settings(settings: &MethodSettings) -> serde_json::Map<String, serde_json::Value> {
    let mut out = NamedSettings::default();
    match settings {
        MethodSettings::Path(s) => {
            out.number("spp", s.spp);
            out.depth(s.length.max_depth);
            out.number("rr_start", s.length.rr_start);
        }
        MethodSettings::Ic(s) => {
            out.ic(s);
            out.flag("gradients", s.gradients);
        }
        MethodSettings::Trc(s) => {
            out.number("at", s.temporal_accuracy);
            out.number("max_life", s.max_life);
            out.text("gradients", s.gradients.name());
            out.flag("reprojection", s.reprojection);
            out.text("next_direct", s.next_direct.name());
            out.flag("keep_paths", s.keep_paths);
            out.flag("history", s.history);
            // `gradients` names the temporal ones here.
            out.flag("spatial_gradients", s.ic.gradients);
            out.ic(&s.ic);
        }
        MethodSettings::Tcg(s) => {
            out.number("tau_min", s.tau_min);
            out.number("tau_max", s.tau_max);
            out.number("max_neighbours", s.max_neighbours);
            out.flag("light_refresh", s.light_refresh);
            out.flag("occlusion_refresh", s.occlusion_refresh);
            out.flag("arrivals", s.arrivals);
            out.ic(&s.ic);
            out.flag("gradients", s.ic.gradients);
        }
        MethodSettings::Movies(s) => {
            out.number("spp", s.spp);
            out.number("shadow_samples", s.shadow_samples);
            out.number("texels_per_pixel", s.texels_per_pixel);
            out.number("max_resolution", s.max_resolution);
            out.number("memory_mib", s.memory_mib);
            out.number("spacing", s.global.spacing);
            out.number("links", s.global.links);
            out.number("bounces", s.global.bounces);
            out.depth(s.length.max_depth);
        }
    }
    out.0
}

/// [`named_settings`]' map as it is filled.
#[derive(Default)]
struct NamedSettings(serde_json::Map<String, serde_json::Value>);

impl NamedSettings {
    /// Through its text, so that an `f32` 0.3 stays 0.3 (not
    /// 0.30000001192092896, as a widening to `f64` would give).
    fn number(&mut self, key: &str, v: impl std::fmt::Display) {
        let text = v.to_string();
        let value = serde_json::from_str(&text).unwrap_or(serde_json::Value::String(text));
        self.0.insert(key.into(), value);
    }

    fn flag(&mut self, key: &str, on: bool) {
        self.0.insert(key.into(), on.into());
    }

    fn text(&mut self, key: &str, v: &str) {
        self.0.insert(key.into(), v.into());
    }

    fn depth(&mut self, max_depth: Option<u32>) {
        match max_depth {
            Some(d) => self.number("max_depth", d),
            None => self.text("max_depth", UNBOUNDED),
        }
    }

    /// `ic`'s record settings, which `trc` and `tcg` make their records
    /// with (its `gradients` aside: `trc`'s are temporal).
    fn ic(&mut self, s: &IcSettings) {
        self.number("accuracy", s.accuracy);
        self.number("spp", s.spp);
        self.text("strata", &format!("{}x{}", s.strata.theta, s.strata.phi));
        self.number("min_spacing", s.min_spacing_px);
        self.number("max_spacing", s.max_spacing_px);
        self.depth(s.length.max_depth);
        self.text(
            "glossy",
            match s.glossy {
                GlossyLobe::Path => "path",
                GlossyLobe::Eas => "eas",
            },
        );
        self.number("eas_tau", s.eas_tau);
    }
}

/// The value inside a one-key object (serde's tag of an enum variant), or
/// `v` itself.
pub fn untagged(v: serde_json::Value) -> serde_json::Value {
    match v {
        serde_json::Value::Object(m) if m.len() == 1 => m
            .into_iter()
            .next()
            .map_or(serde_json::Value::Null, |(_, v)| v),
        v => v,
    }
}

/// Applies setting `key = v` to `settings`.
fn apply(settings: &mut MethodSettings, key: &str, v: &str) -> Result<(), MethodError> {
    let method = settings.name();
    let known = match settings {
        MethodSettings::Path(s) => path_setting(method, key, v, s)?,
        MethodSettings::Ic(s) => {
            ic_setting(method, key, v, s)? || glossy_setting(method, key, v, s)?
        }
        MethodSettings::Trc(s) => trc_setting(method, key, v, s)?,
        MethodSettings::Tcg(s) => tcg_setting(method, key, v, s)?,
        MethodSettings::Movies(s) => movies_setting(method, key, v, s)?,
    };
    if !known {
        return Err(MethodError::UnknownKey {
            method: method.into(),
            key: key.into(),
            known: known_keys(method),
        });
    }
    Ok(())
}

/// Applies `path`'s setting `key = v` to `s`; `false` when `key` is none
/// of them.
fn path_setting(
    method: &str,
    key: &str,
    v: &str,
    s: &mut PathSettings,
) -> Result<bool, MethodError> {
    match key {
        "spp" => s.spp = value(method, key, v, limits::SPP)?,
        "max_depth" => s.length.max_depth = depth(method, key, v)?,
        "rr_start" => s.length.rr_start = value(method, key, v, limits::PATH_DEPTH)?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// Applies the radiance-record setting `key = v` to `s` (`ic`, `trc`,
/// `tcg`); `false` when `key` is none of them.
fn glossy_setting(
    method: &str,
    key: &str,
    v: &str,
    s: &mut IcSettings,
) -> Result<bool, MethodError> {
    match key {
        "glossy" => {
            s.glossy = match v.trim() {
                "path" => GlossyLobe::Path,
                "eas" => GlossyLobe::Eas,
                _ => {
                    return Err(MethodError::BadValue {
                        method: method.into(),
                        key: key.into(),
                        value: v.into(),
                        problem: "expected path or eas".into(),
                    })
                }
            }
        }
        "eas_tau" => s.eas_tau = value(method, key, v, limits::EAS_TAU)?,
        _ => return Ok(false),
    }
    Ok(true)
}

/// Applies `trc`'s setting `key = v` to `s`: its temporal ones, and
/// `ic`'s, with which it makes its records (`gradients` names the
/// temporal ones here); `false` when `key` is none of them.
fn trc_setting(method: &str, key: &str, v: &str, s: &mut TrcSettings) -> Result<bool, MethodError> {
    match key {
        "at" => s.temporal_accuracy = value(method, key, v, limits::TEMPORAL_ACCURACY)?,
        "max_life" => s.max_life = value(method, key, v, limits::MAX_LIFE)?,
        "gradients" => {
            s.gradients = match v.trim() {
                "none" => TemporalGradients::None,
                "extrapolated" => TemporalGradients::Extrapolated,
                "interpolated" => TemporalGradients::Interpolated,
                _ => {
                    return Err(MethodError::BadValue {
                        method: method.into(),
                        key: key.into(),
                        value: v.into(),
                        problem: "expected none, extrapolated or interpolated".into(),
                    })
                }
            }
        }
        "reprojection" => s.reprojection = flag(method, key, v)?,
        "next_direct" => {
            s.next_direct = match v.trim() {
                "moving-lights" => NextDirect::MovingLights,
                "long-lives" => NextDirect::LongLives,
                _ => match flag(method, key, v) {
                    Ok(true) => NextDirect::On,
                    Ok(false) => NextDirect::Off,
                    Err(_) => {
                        return Err(MethodError::BadValue {
                            method: method.into(),
                            key: key.into(),
                            value: v.into(),
                            problem: "expected off, moving-lights, long-lives or on (or 0/1)"
                                .into(),
                        })
                    }
                },
            }
        }
        "keep_paths" => s.keep_paths = flag(method, key, v)?,
        "history" => s.history = flag(method, key, v)?,
        // `ic`'s `gradients` (spatial), which `gradients` names no more here.
        "spatial_gradients" => s.ic.gradients = flag(method, key, v)?,
        _ => {
            return Ok(ic_setting(method, key, v, &mut s.ic)?
                || glossy_setting(method, key, v, &mut s.ic)?)
        }
    }
    Ok(true)
}

/// Applies `tcg`'s setting `key = v` to `s`: Eq. 2's shares, §4.2's
/// neighbour bound, and `ic`'s, with which it makes its records; `false`
/// when `key` is none of them.
fn tcg_setting(method: &str, key: &str, v: &str, s: &mut TcgSettings) -> Result<bool, MethodError> {
    match key {
        "tau_min" => s.tau_min = value(method, key, v, limits::SHARE)?,
        "tau_max" => s.tau_max = value(method, key, v, limits::SHARE)?,
        "max_neighbours" => s.max_neighbours = value(method, key, v, limits::MAX_NEIGHBOURS)?,
        "light_refresh" => s.light_refresh = flag(method, key, v)?,
        "occlusion_refresh" => s.occlusion_refresh = flag(method, key, v)?,
        "arrivals" => s.arrivals = flag(method, key, v)?,
        _ => {
            return Ok(ic_setting(method, key, v, &mut s.ic)?
                || glossy_setting(method, key, v, &mut s.ic)?)
        }
    }
    Ok(true)
}

/// Applies `movies`' setting `key = v` to `s`; `false` when `key` is
/// none of them.
fn movies_setting(
    method: &str,
    key: &str,
    v: &str,
    s: &mut MoviesSettings,
) -> Result<bool, MethodError> {
    match key {
        "spp" => s.spp = value(method, key, v, limits::SPP)?,
        "shadow_samples" => s.shadow_samples = value(method, key, v, limits::SHADOW_SAMPLES)?,
        "texels_per_pixel" => s.texels_per_pixel = value(method, key, v, limits::TEXELS_PER_PIXEL)?,
        "max_resolution" => s.max_resolution = value(method, key, v, limits::MAX_RESOLUTION)?,
        "memory_mib" => s.memory_mib = value(method, key, v, limits::MEMORY_MIB)?,
        "spacing" => s.global.spacing = value(method, key, v, limits::GRID_SPACING)?,
        "links" => s.global.links = value(method, key, v, limits::LINKS)?,
        "bounces" => s.global.bounces = value(method, key, v, limits::BOUNCES)?,
        "max_depth" => s.length.max_depth = depth(method, key, v)?,
        _ => return Ok(false),
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A value outside the range and one that is no number of the
    /// setting's kind are refused in the same words (`spp=0` said
    /// "expected 1 to 1000000", `spp=-1` "expected a number from 1 to
    /// 1000000").
    #[test]
    fn every_refused_value_says_the_same() {
        let want = Err("expected a number from 1 to 1000000".to_string());
        for text in ["0", "-1", "1000001", "lots", "1.5", ""] {
            assert_eq!(limits::SPP.parse(text), want, "{text:?}");
        }
        assert_eq!(limits::SPP.parse("16"), Ok(16));
        for text in ["0", "-0.2", "2.5", "NaN", "x"] {
            assert_eq!(
                limits::ACCURACY.parse(text),
                Err("expected a number from 0.001 to 2".to_string()),
                "{text:?}"
            );
        }
    }

    /// What [`named_settings`] shows, given back by name (as a client
    /// posts a job's settings again), makes the same settings: for every
    /// method's defaults and each listed key at its example value. It names
    /// every listed key, and only those.
    #[test]
    fn named_settings_make_the_same_settings_again() {
        let as_text = |v: &serde_json::Value| match v {
            serde_json::Value::String(s) => s.clone(),
            other => other.to_string(),
        };
        for m in METHODS {
            let changes = std::iter::once(None).chain(m.keys.iter().map(Some));
            for change in changes {
                let settings = method_settings(m.name, change.map(|&(k, v)| (k, v))).unwrap();
                let named = named_settings(&settings);
                let pairs: Vec<(String, String)> =
                    named.iter().map(|(k, v)| (k.clone(), as_text(v))).collect();
                let again = method_settings(m.name, pairs.iter().map(|(k, v)| (&k[..], &v[..])));
                assert_eq!(
                    again.as_ref(),
                    Ok(&settings),
                    "{} {change:?}: {named:?}",
                    m.name
                );
                let mut listed: Vec<&str> = m.keys.iter().map(|(k, _)| *k).collect();
                let mut names: Vec<&str> = named.keys().map(|k| k.as_str()).collect();
                listed.sort_unstable();
                names.sort_unstable();
                assert_eq!(names, listed, "{}", m.name);
            }
        }
        let trc = named_settings(&method_settings("trc", [("keep_paths", "on")]).unwrap());
        assert_eq!(trc["keep_paths"], serde_json::Value::Bool(true));
        assert_eq!(trc["at"].to_string(), "0.05");
        assert_eq!(trc["gradients"], "extrapolated");
    }

    /// `max_depth` "none" leaves paths unbounded, as by default, for every
    /// method with pixel paths; a bad value says "none" is taken too.
    #[test]
    fn max_depth_none_is_unbounded() {
        for m in METHODS
            .iter()
            .filter(|m| m.keys.iter().any(|(k, _)| *k == "max_depth"))
        {
            let bounded = method_settings(m.name, [("max_depth", "8")]).unwrap();
            let unbounded = method_settings(m.name, [("max_depth", "8"), ("max_depth", " none")]);
            assert_eq!(unbounded, method_settings(m.name, []), "{}", m.name);
            assert_ne!(unbounded.unwrap(), bounded, "{}", m.name);
            assert_eq!(named_settings(&bounded)["max_depth"], 8, "{}", m.name);
        }
        let err = method_settings("path", [("max_depth", "deep")]).unwrap_err();
        assert!(err.to_string().contains("or none (unbounded)"), "{err}");
    }

    /// On/off settings take what the CLI's flags and JSON's booleans give;
    /// a number setting takes no boolean.
    #[test]
    fn flags_take_on_and_off() {
        for (v, on) in [
            ("1", true),
            ("on", true),
            ("true", true),
            ("off", false),
            ("false", false),
        ] {
            let s = method_settings("trc", [("reprojection", v)]).unwrap();
            assert!(
                matches!(s, MethodSettings::Trc(t) if t.reprojection == on),
                "{v}"
            );
        }
        assert!(method_settings("trc", [("reprojection", "2")]).is_err());
        assert!(method_settings("trc", [("at", "true")]).is_err());
    }

    #[test]
    fn every_listed_key_is_accepted() {
        for m in METHODS {
            method_settings(m.name, []).unwrap();
            for (key, example) in m.keys {
                method_settings(m.name, [(*key, *example)])
                    .unwrap_or_else(|e| panic!("{}:{key}={example}: {e}", m.name));
            }
        }
    }

    /// `trc` takes `ic`'s record settings into the `ic` settings it makes
    /// its records with, while its `gradients` stays the temporal one.
    #[test]
    fn trc_takes_the_record_settings_of_ic() {
        let trc = |key, v| match method_settings("trc", Some((key, v))).unwrap() {
            MethodSettings::Trc(s) => s,
            other => panic!("{other:?}"),
        };
        let strata = trc("strata", "64x32").ic.strata;
        assert_eq!((strata.theta, strata.phi), (64, 32));
        assert_eq!(trc("max_spacing", "8").ic.max_spacing_px, 8.0);
        assert_eq!(trc("min_spacing", "3").ic.min_spacing_px, 3.0);
        let gradients = trc("gradients", "none");
        assert_eq!(gradients.gradients, TemporalGradients::None);
        assert!(gradients.ic.gradients, "spatial gradients stay on");
        assert!(matches!(
            method_settings("trc", Some(("strata", "64"))),
            Err(MethodError::BadValue { .. })
        ));
    }

    /// Several settings apply in order, each checked; a later one of the
    /// same key wins.
    #[test]
    fn several_settings_apply_in_order() {
        let s = method_settings("trc", [("at", "0.02"), ("max_life", "3"), ("at", "0.1")]).unwrap();
        let MethodSettings::Trc(s) = s else {
            panic!("{s:?}")
        };
        assert_eq!((s.temporal_accuracy, s.max_life), (0.1, 3));
        assert!(matches!(
            method_settings("ic", [("accuracy", "0.3"), ("at", "0.1")]),
            Err(MethodError::UnknownKey { .. })
        ));
        assert!(matches!(
            method_settings("radiosity", []),
            Err(MethodError::UnknownMethod { .. })
        ));
    }
}
