//! The methods `radcache bench --methods` accepts, and how a
//! specification (`NAME` or `NAME:KEY=V1,V2,…`) becomes their settings.

use crate::cache::gather::Strata;
use crate::method::ic::IcSettings;
use crate::method::path::PathSettings;
use crate::method::trc::{TemporalGradients, TrcSettings};
use crate::render::MethodSettings;
use anyhow::Result;
use std::ops::Range;

/// A method the bench knows, and the settings a sweep may vary.
pub struct MethodInfo {
    pub name: &'static str,
    /// `(key, example value)`: every key [`method_settings`] accepts for
    /// this method, with a value it accepts (checked by a unit test).
    pub keys: &'static [(&'static str, &'static str)],
}

/// Every method `radcache bench --methods` accepts. Keep in step with
/// [`method_settings`].
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
        ],
    },
    MethodInfo {
        name: "trc",
        keys: &[
            ("at", "0.05"),
            ("max_life", "20"),
            ("gradients", "extrapolated"),
            ("reprojection", "1"),
            ("next_direct", "0"),
            ("spp", "4"),
            ("accuracy", "0.2"),
            ("strata", "16x48"),
            ("min_spacing", "2"),
            ("max_spacing", "64"),
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
    #[error("bad method specification '{spec}': {problem} (expected NAME or NAME:KEY=V1,V2,…, e.g. path:spp=4,16,64)")]
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

/// Parses `value` of setting `key` of `method` as a `T` in `range`.
fn value<T>(method: &str, key: &str, value: &str, range: Range<T>) -> Result<T, MethodError>
where
    T: std::str::FromStr + PartialOrd + std::fmt::Display + Copy,
{
    let bad = |problem: String| MethodError::BadValue {
        method: method.into(),
        key: key.into(),
        value: value.into(),
        problem,
    };
    let v: T = value
        .trim()
        .parse()
        .map_err(|_| bad("not a number of the right kind".into()))?;
    if !(range.start <= v && v < range.end) {
        return Err(bad(format!(
            "out of range {}..{} (end exclusive)",
            range.start, range.end
        )));
    }
    Ok(v)
}

/// Applies `ic`'s setting `key = v` to `s` (also for `trc`, whose records
/// are `ic`'s); `false` when `key` is none of them.
fn ic_setting(method: &str, key: &str, v: &str, s: &mut IcSettings) -> Result<bool, MethodError> {
    match key {
        "accuracy" => s.accuracy = value(method, key, v, 0.001..2.001)?,
        "spp" => s.spp = value(method, key, v, 1..1_000_001)?,
        "strata" => {
            let (m, n) = v.split_once('x').ok_or_else(|| MethodError::BadValue {
                method: method.into(),
                key: key.into(),
                value: v.into(),
                problem: "expected MxN, e.g. 16x48".into(),
            })?;
            s.strata = Strata {
                theta: value(method, key, m, 1..1025)?,
                phi: value(method, key, n, 1..4097)?,
            };
        }
        "min_spacing" => s.min_spacing_px = value(method, key, v, 0.001..1e6)?,
        "max_spacing" => s.max_spacing_px = value(method, key, v, 0.001..1e6)?,
        "gradients" => s.gradients = value::<u8>(method, key, v, 0..2)? == 1,
        _ => return Ok(false),
    }
    Ok(true)
}

/// The settings of `method` with its defaults, and `setting = (key, value)`
/// applied when given. **The one place that maps names to
/// [`MethodSettings`]**: a new method adds an arm here and a row to
/// [`METHODS`].
pub fn method_settings(
    method: &str,
    setting: Option<(&str, &str)>,
) -> Result<MethodSettings, MethodError> {
    let unknown_key = |key: &str| MethodError::UnknownKey {
        method: method.into(),
        key: key.into(),
        known: known_keys(method),
    };
    match method {
        "path" => {
            let mut s = PathSettings::default();
            if let Some((key, v)) = setting {
                match key {
                    "spp" => s.spp = value(method, key, v, 1..1_000_001)?,
                    "max_depth" => s.length.max_depth = Some(value(method, key, v, 0..10_001)?),
                    "rr_start" => s.length.rr_start = value(method, key, v, 0..10_001)?,
                    _ => return Err(unknown_key(key)),
                }
            }
            Ok(MethodSettings::Path(s))
        }
        "ic" => {
            let mut s = IcSettings::default();
            if let Some((key, v)) = setting {
                if !ic_setting(method, key, v, &mut s)? {
                    return Err(unknown_key(key));
                }
            }
            Ok(MethodSettings::Ic(s))
        }
        "trc" => {
            let mut s = TrcSettings::default();
            if let Some((key, v)) = setting {
                match key {
                    "at" => s.temporal_accuracy = value(method, key, v, 1e-6..1e6)?,
                    "max_life" => s.max_life = value(method, key, v, 1..100_001)?,
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
                    "reprojection" => s.reprojection = value::<u8>(method, key, v, 0..2)? == 1,
                    "next_direct" => s.next_direct = value::<u8>(method, key, v, 0..2)? == 1,
                    // `gradients` above names the temporal ones; the
                    // rest are `ic`'s, whose records `trc` makes.
                    _ => {
                        if !ic_setting(method, key, v, &mut s.ic)? {
                            return Err(unknown_key(key));
                        }
                    }
                }
            }
            Ok(MethodSettings::Trc(s))
        }
        _ => Err(MethodError::UnknownMethod {
            name: method.into(),
            known: known_methods(),
        }),
    }
}

/// Records (irradiance or radiance records, texture movies, …) a method
/// computed during the last run; 0 for methods without records (`path`).
/// A method with records reports them here.
/// One method with an optional sweep of one setting:
/// `path` (defaults) or `path:spp=4,16,64` (one run per value).
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSweep {
    pub method: String,
    /// `None`: one run with the defaults.
    pub key: Option<String>,
    pub values: Vec<String>,
}

impl MethodSweep {
    /// Parses `NAME` or `NAME:KEY=V1,V2,…` and checks every value against
    /// [`method_settings`], so a typo fails before anything renders.
    pub fn parse(spec: &str) -> Result<Self, MethodError> {
        let bad = |problem: &str| MethodError::BadSpec {
            spec: spec.into(),
            problem: problem.into(),
        };
        let (method, sweep) = match spec.split_once(':') {
            Some((m, s)) => (m.trim(), Some(s)),
            None => (spec.trim(), None),
        };
        if method.is_empty() {
            return Err(bad("no method name"));
        }
        let sweep = match sweep {
            None => MethodSweep {
                method: method.into(),
                key: None,
                values: Vec::new(),
            },
            Some(s) => {
                let (key, values) = s
                    .split_once('=')
                    .ok_or_else(|| bad("no '=' after the setting"))?;
                let key = key.trim();
                if key.is_empty() {
                    return Err(bad("no setting name before '='"));
                }
                let values: Vec<String> = values.split(',').map(|v| v.trim().to_string()).collect();
                if values.iter().any(String::is_empty) {
                    return Err(bad("empty value in the list"));
                }
                MethodSweep {
                    method: method.into(),
                    key: Some(key.into()),
                    values,
                }
            }
        };
        for run in sweep.runs() {
            run.settings()?;
        }
        Ok(sweep)
    }

    /// The runs of the sweep, in the order given.
    pub fn runs(&self) -> Vec<RunSpec> {
        match &self.key {
            None => vec![RunSpec {
                method: self.method.clone(),
                setting: None,
            }],
            Some(key) => self
                .values
                .iter()
                .map(|v| RunSpec {
                    method: self.method.clone(),
                    setting: Some((key.clone(), v.clone())),
                })
                .collect(),
        }
    }
}

/// One run: a method and at most one setting changed from its defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    pub method: String,
    pub setting: Option<(String, String)>,
}

impl RunSpec {
    pub fn settings(&self) -> Result<MethodSettings, MethodError> {
        method_settings(
            &self.method,
            self.setting.as_ref().map(|(k, v)| (k.as_str(), v.as_str())),
        )
    }

    /// `spp=4`, or `default`.
    pub fn label(&self) -> String {
        match &self.setting {
            Some((k, v)) => format!("{k}={v}"),
            None => "default".into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_key_is_accepted() {
        for m in METHODS {
            method_settings(m.name, None).unwrap();
            for (key, example) in m.keys {
                method_settings(m.name, Some((key, example)))
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

    #[test]
    fn sweep_parses_and_applies_values() {
        let s = MethodSweep::parse("path:spp=4, 16,64").unwrap();
        assert_eq!(s.values, ["4", "16", "64"]);
        let spps: Vec<u32> = s
            .runs()
            .iter()
            .map(|r| {
                #[allow(unreachable_patterns)]
                match r.settings().unwrap() {
                    MethodSettings::Path(p) => p.spp,
                    other => panic!("{other:?}"),
                }
            })
            .collect();
        assert_eq!(spps, [4, 16, 64]);
        assert_eq!(s.runs()[0].label(), "spp=4");
        let d = MethodSweep::parse("path").unwrap();
        assert_eq!(d.runs().len(), 1);
        assert_eq!(d.runs()[0].label(), "default");
    }

    #[test]
    fn bad_specs_are_errors() {
        for spec in [
            "",
            ":spp=4",
            "path:spp",
            "path:=4",
            "path:spp=4,,8",
            "path:spp=0",
        ] {
            assert!(MethodSweep::parse(spec).is_err(), "{spec}");
        }
        let e = MethodSweep::parse("path:spp=lots").unwrap_err().to_string();
        assert!(e.contains("lots") && e.contains("spp"), "{e}");
    }
}
