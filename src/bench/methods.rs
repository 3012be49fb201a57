//! The methods `radcache bench --methods` accepts, and how a
//! specification (`NAME`, `NAME:KEY=V1,V2,…` or `NAME:KEY=V:KEY=V1,V2,…`)
//! becomes their settings ([`crate::method::settings`]).

pub use crate::method::settings::{method_settings, MethodError, MethodInfo, METHODS};
use crate::render::MethodSettings;

/// One method, the settings it changes from its defaults, and at most one
/// of them swept: `path` (defaults), `path:spp=4,16,64` (one run per
/// value) or `trc:at=100000:max_life=2,5,20` (`at` fixed in every run,
/// `max_life` swept).
#[derive(Clone, Debug, PartialEq)]
pub struct MethodSweep {
    pub method: String,
    /// The settings each run changes alike, in the order given.
    pub fixed: Vec<(String, String)>,
    /// The setting swept and its values, one run each; `None`: one run.
    pub swept: Option<(String, Vec<String>)>,
}

impl MethodSweep {
    /// Parses `NAME[:KEY=V1,V2,…[:KEY=V…]]` (at most one setting with
    /// several values, no setting twice) and checks every value against
    /// [`method_settings`], so a typo fails before anything renders.
    pub fn parse(spec: &str) -> Result<Self, MethodError> {
        let bad = |problem: &str| MethodError::BadSpec {
            spec: spec.into(),
            problem: problem.into(),
        };
        let mut parts = spec.split(':');
        let method = parts.next().unwrap_or_default().trim();
        if method.is_empty() {
            return Err(bad("no method name"));
        }
        let mut sweep = MethodSweep {
            method: method.into(),
            fixed: Vec::new(),
            swept: None,
        };
        for part in parts {
            let (key, values) = part
                .split_once('=')
                .ok_or_else(|| bad("no '=' after the setting"))?;
            let key = key.trim();
            if key.is_empty() {
                return Err(bad("no setting name before '='"));
            }
            if sweep.changes(key) {
                return Err(bad(&format!("setting {key} given twice")));
            }
            let values: Vec<String> = values.split(',').map(|v| v.trim().to_string()).collect();
            if values.iter().any(String::is_empty) {
                return Err(bad("empty value in the list"));
            }
            if values.len() == 1 {
                sweep.fixed.push((key.into(), values[0].clone()));
            } else if sweep.swept.is_some() {
                return Err(bad("more than one setting lists several values"));
            } else {
                sweep.swept = Some((key.into(), values));
            }
        }
        for run in sweep.runs() {
            run.settings()?;
        }
        Ok(sweep)
    }

    /// Whether the sweep changes setting `key`, fixed or swept.
    fn changes(&self, key: &str) -> bool {
        self.fixed.iter().any(|(k, _)| k == key)
            || self.swept.as_ref().is_some_and(|(k, _)| k == key)
    }

    /// The runs of the sweep, in the order of the swept values.
    pub fn runs(&self) -> Vec<RunSpec> {
        let run = |swept: Option<(&String, &String)>| RunSpec {
            method: self.method.clone(),
            settings: self
                .fixed
                .iter()
                .cloned()
                .chain(swept.map(|(k, v)| (k.clone(), v.clone())))
                .collect(),
        };
        match &self.swept {
            None => vec![run(None)],
            Some((key, values)) => values.iter().map(|v| run(Some((key, v)))).collect(),
        }
    }
}

/// One run: a method and the settings changed from its defaults (the
/// swept one last).
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    pub method: String,
    pub settings: Vec<(String, String)>,
}

impl RunSpec {
    pub fn settings(&self) -> Result<MethodSettings, MethodError> {
        method_settings(
            &self.method,
            self.settings.iter().map(|(k, v)| (k.as_str(), v.as_str())),
        )
    }

    /// `spp=4`, `at=100000 max_life=5` (the swept setting last), or
    /// `default`. Charts split it at its last `=` into the series and the
    /// point (`bench::charts`).
    pub fn label(&self) -> String {
        if self.settings.is_empty() {
            return "default".into();
        }
        let pairs: Vec<String> = self
            .settings
            .iter()
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        pairs.join(" ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_parses_and_applies_values() {
        let s = MethodSweep::parse("path:spp=4, 16,64").unwrap();
        assert_eq!(
            s.swept,
            Some(("spp".into(), vec!["4".into(), "16".into(), "64".into()]))
        );
        let spps: Vec<u32> = s
            .runs()
            .iter()
            .map(|r| match r.settings().unwrap() {
                MethodSettings::Path(p) => p.spp,
                other => panic!("{other:?}"),
            })
            .collect();
        assert_eq!(spps, [4, 16, 64]);
        assert_eq!(s.runs()[0].label(), "spp=4");
        let d = MethodSweep::parse("path").unwrap();
        assert_eq!(d.runs().len(), 1);
        assert_eq!(d.runs()[0].label(), "default");
    }

    #[test]
    fn fixed_settings_apply_to_every_run_of_a_sweep() {
        let s = MethodSweep::parse("trc:at=100000:max_life=2,5").unwrap();
        let runs = s.runs();
        let labels: Vec<String> = runs.iter().map(RunSpec::label).collect();
        assert_eq!(labels, ["at=100000 max_life=2", "at=100000 max_life=5"]);
        for (run, life) in runs.iter().zip([2, 5]) {
            match run.settings().unwrap() {
                MethodSettings::Trc(t) => {
                    assert_eq!((t.temporal_accuracy, t.max_life), (1e5, life));
                }
                other => panic!("{other:?}"),
            }
        }
        // The swept setting comes last in the label whatever its place.
        let s = MethodSweep::parse("trc:max_life=2,5:at=0.1").unwrap();
        assert_eq!(s.runs()[1].label(), "at=0.1 max_life=5");
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
            "path:spp=4:",
            "trc:at=0.1,0.2:max_life=2,5",
            "trc:at=0.1:at=0.2",
            "trc:at=0.1:max_life=0",
        ] {
            assert!(MethodSweep::parse(spec).is_err(), "{spec}");
        }
        let e = MethodSweep::parse("path:spp=lots").unwrap_err().to_string();
        assert!(e.contains("lots") && e.contains("spp"), "{e}");
    }
}
