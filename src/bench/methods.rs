//! The methods `radcache bench --methods` accepts, and how a
//! specification (`NAME` or `NAME:KEY=V1,V2,…`) becomes their settings
//! ([`crate::method::settings`]).

pub use crate::method::settings::{method_settings, MethodError, MethodInfo, METHODS};
use crate::render::MethodSettings;

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
