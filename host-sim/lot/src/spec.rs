//! The lot's specification (a TOML file, host-sim/lot/README.md "The spec"): per
//! parameter the limits of its deviation from the model, and the verdicts a good device
//! may have; a device passes when it was diagnosed, every specified parameter lies within
//! its limits and its verdict is accepted.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result, bail};
use paragyro_diagnose::diagnose::Answer;
use paragyro_diagnose::diagnose::calibrate::PARAM_NAMES;
use serde::{Deserialize, Serialize};

use crate::row::LotRow;

/// Which deviation a limit bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Deviation {
    /// `(device − model)/|model|` (report.json's `relative`; the row's `{p}_rel`).
    #[default]
    Relative,
    /// `device − model`, in the parameter's own unit (non-dimensional, γ: rad per τ).
    Absolute,
}

/// The limits of one parameter's deviation; either may be absent (a one-sided limit).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limit {
    /// Which deviation (default `relative`).
    #[serde(default)]
    pub deviation: Deviation,
    /// The lowest deviation in spec.
    pub lo: Option<f64>,
    /// The highest deviation in spec.
    pub hi: Option<f64>,
}

impl Limit {
    /// The deviation this limit bounds, of `row`'s parameter `name` (`None`: not
    /// calibrated, or `relative` with a model value of 0).
    pub fn deviation_of(&self, row: &LotRow, name: &str) -> Option<f64> {
        let p = row.param(name)?;
        match self.deviation {
            Deviation::Relative => p.rel,
            Deviation::Absolute => Some(p.device - p.model),
        }
    }

    /// `x` lies within the limits (bounds included).
    pub fn contains(&self, x: f64) -> bool {
        self.lo.is_none_or(|lo| x >= lo) && self.hi.is_none_or(|hi| x <= hi)
    }
}

fn default_accept() -> Vec<String> {
    vec!["none".into()]
}

/// The lot's specification (see the module's docs; the example is `spec.example.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// A name for the report's title.
    #[serde(default)]
    pub name: Option<String>,
    /// The verdicts a passing device may have (`none`, `unknown` or effect names); default
    /// `["none"]`.
    #[serde(default = "default_accept")]
    pub accept_verdicts: Vec<String>,
    /// The limits by parameter name (report.json's names: `wy2`, `mu_x`, …).
    #[serde(default)]
    pub parameters: BTreeMap<String, Limit>,
}

impl Default for Spec {
    /// No parameter limits; only the verdict `none` passes.
    fn default() -> Self {
        Spec {
            name: None,
            accept_verdicts: default_accept(),
            parameters: BTreeMap::new(),
        }
    }
}

/// Why a device fails the spec (empty: it passes).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Judgement {
    /// One reason per failed item: `error`, `verdict unknown`, `wy2 +1.2e-2 > hi 1e-2`, …
    pub reasons: Vec<String>,
    /// Some parameter is outside its limits or has no value.
    pub parametric_fail: bool,
}

impl Judgement {
    /// The device passes.
    pub fn pass(&self) -> bool {
        self.reasons.is_empty()
    }
}

impl Spec {
    /// Reads and checks a spec file.
    pub fn load(path: &Path) -> Result<Spec> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the spec {}", path.display()))?;
        Spec::parse(&text).with_context(|| format!("the spec {}", path.display()))
    }

    /// Parses and checks a spec's TOML text.
    pub fn parse(text: &str) -> Result<Spec> {
        let spec: Spec = toml::from_str(text).context("not a valid spec")?;
        spec.check()?;
        Ok(spec)
    }

    /// Known parameter names, finite limits with lo ≤ hi, at least one limit each, and
    /// verdicts that exist.
    pub fn check(&self) -> Result<()> {
        for (name, l) in &self.parameters {
            if !PARAM_NAMES.contains(&name.as_str()) {
                bail!(
                    "unknown parameter '{name}' (the parameters: {})",
                    PARAM_NAMES.join(", ")
                );
            }
            if l.lo.is_none() && l.hi.is_none() {
                bail!("parameter '{name}': give lo, hi or both");
            }
            if l.lo.into_iter().chain(l.hi).any(|x| !x.is_finite()) {
                bail!("parameter '{name}': the limits must be finite numbers");
            }
            if let (Some(lo), Some(hi)) = (l.lo, l.hi)
                && lo > hi
            {
                bail!("parameter '{name}': lo {lo} is above hi {hi}");
            }
        }
        for v in &self.accept_verdicts {
            v.parse::<Answer>()
                .map_err(|e| anyhow::anyhow!("accept_verdicts: {e}"))?;
        }
        Ok(())
    }

    /// How `row` fares against the spec.
    pub fn judge(&self, row: &LotRow) -> Judgement {
        let mut j = Judgement::default();
        if let Some(e) = &row.error {
            j.reasons.push(format!("error: {e}"));
            return j;
        }
        match &row.verdict {
            Some(v) if self.accept_verdicts.contains(v) => {}
            Some(v) => j.reasons.push(format!("verdict {v}")),
            None => j.reasons.push("no verdict".into()),
        }
        for (name, l) in &self.parameters {
            match l.deviation_of(row, name) {
                None => {
                    j.parametric_fail = true;
                    j.reasons.push(format!("{name}: no value"));
                }
                Some(x) if !l.contains(x) => {
                    j.parametric_fail = true;
                    j.reasons.push(match (l.lo, l.hi) {
                        (Some(lo), _) if x < lo => format!("{name} {x:+.3e} < lo {lo:e}"),
                        (_, Some(hi)) if x > hi => format!("{name} {x:+.3e} > hi {hi:e}"),
                        _ => format!("{name} {x:+.3e} outside the limits"),
                    });
                }
                Some(_) => {}
            }
        }
        j
    }
}

/// The yield of a lot against a spec.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Yield {
    /// Rows (devices).
    pub devices: usize,
    /// Devices read and diagnosed.
    pub diagnosed: usize,
    /// Devices that pass (diagnosed, every limit, an accepted verdict).
    pub passed: usize,
    /// Diagnosed devices within every parameter limit, whatever their verdict.
    pub parametric_passed: usize,
    /// `passed / devices` (a device that could not be read fails); null for an empty lot.
    pub yield_all: Option<f64>,
    /// `passed / diagnosed`.
    pub yield_diagnosed: Option<f64>,
    /// `parametric_passed / diagnosed`.
    pub parametric_yield: Option<f64>,
}

fn ratio(a: usize, b: usize) -> Option<f64> {
    (b > 0).then(|| a as f64 / b as f64)
}

impl Spec {
    /// The yield of `rows`.
    pub fn yield_of(&self, rows: &[LotRow]) -> Yield {
        let mut y = Yield {
            devices: rows.len(),
            diagnosed: 0,
            passed: 0,
            parametric_passed: 0,
            yield_all: None,
            yield_diagnosed: None,
            parametric_yield: None,
        };
        for r in rows {
            if !r.diagnosed() {
                continue;
            }
            y.diagnosed += 1;
            let j = self.judge(r);
            y.passed += usize::from(j.pass());
            y.parametric_passed += usize::from(!j.parametric_fail);
        }
        y.yield_all = ratio(y.passed, y.devices);
        y.yield_diagnosed = ratio(y.passed, y.diagnosed);
        y.parametric_yield = ratio(y.parametric_passed, y.diagnosed);
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made row: verdict, and `wy2`'s and `mu_x`'s values (model 1.0 and 2.0).
    fn row(verdict: &str, wy2_rel: Option<f64>, mu_x_device: f64) -> LotRow {
        let mut r = LotRow {
            record: format!("{verdict}.csv"),
            verdict: Some(verdict.into()),
            ..LotRow::default()
        };
        let mut set = |p: &str, model: f64, device: f64, rel: Option<f64>| {
            for (s, v) in [
                ("model", Some(model)),
                ("device", Some(device)),
                ("sigma", Some(1e-6)),
                ("rel", rel),
                ("rel_sigma", rel.map(|_| 1e-6)),
                ("t", Some(3.0)),
            ] {
                if let Some(v) = v {
                    r.values.insert(format!("{p}_{s}"), Some(v));
                }
            }
        };
        set("wy2", 1.0, 1.0 + wy2_rel.unwrap_or(0.0), wy2_rel);
        set("mu_x", 2.0, mu_x_device, Some((mu_x_device - 2.0) / 2.0));
        r
    }

    const SPEC: &str = "
name = \"test\"
accept_verdicts = [\"none\", \"thermal_drift\"]
[parameters.wy2]
lo = -0.01
hi = 0.01
[parameters.mu_x]
deviation = \"absolute\"
hi = 0.5
";

    #[test]
    fn the_yield_of_hand_made_rows() {
        let spec = Spec::parse(SPEC).unwrap();
        let rows = vec![
            row("none", Some(0.005), 2.1),        // passes
            row("none", Some(0.01), 2.5),         // passes: the limits are inclusive
            row("none", Some(0.02), 2.0),         // wy2 above hi
            row("none", Some(-0.011), 2.0),       // wy2 below lo
            row("unknown", Some(0.0), 2.0),       // verdict only
            row("thermal_drift", Some(0.0), 2.0), // an accepted effect
            row("none", Some(0.0), 2.6),          // mu_x's absolute deviation 0.6 > 0.5
            row("none", None, 2.0),               // wy2 has no relative value
            LotRow::failed("x.csv", "lot/x.csv", "cannot read".into()),
        ];
        let pass: Vec<bool> = rows.iter().map(|r| spec.judge(r).pass()).collect();
        assert_eq!(
            pass,
            [true, true, false, false, false, true, false, false, false]
        );
        let y = spec.yield_of(&rows);
        assert_eq!((y.devices, y.diagnosed, y.passed), (9, 8, 3));
        // parametric: all but the two wy2 outliers, mu_x's and the missing wy2
        assert_eq!(y.parametric_passed, 4);
        assert_eq!(y.yield_all, Some(3.0 / 9.0));
        assert_eq!(y.yield_diagnosed, Some(3.0 / 8.0));
        assert_eq!(y.parametric_yield, Some(4.0 / 8.0));
        let j = spec.judge(&rows[2]);
        assert_eq!(j.reasons, ["wy2 +2.000e-2 > hi 1e-2"]);
        assert_eq!(spec.judge(&rows[3]).reasons, ["wy2 -1.100e-2 < lo -1e-2"]);
        assert_eq!(spec.judge(&rows[4]).reasons, ["verdict unknown"]);
        assert_eq!(spec.judge(&rows[7]).reasons, ["wy2: no value"]);
        // the default spec: the verdict alone
        let d = Spec::default().yield_of(&rows);
        assert_eq!((d.passed, d.parametric_passed), (6, 8));
        assert_eq!(Spec::default().yield_of(&[]).yield_all, None);
    }

    #[test]
    fn bad_specs_are_refused_with_the_reason() {
        let err = |t: &str| format!("{:#}", Spec::parse(t).unwrap_err());
        assert!(err("[parameters.wz2]\nhi = 1\n").contains("unknown parameter 'wz2'"));
        assert!(err("[parameters.wy2]\nlo = 1\nhi = 0\n").contains("lo 1 is above hi 0"));
        assert!(err("[parameters.wy2]\n").contains("give lo, hi or both"));
        assert!(err("[parameters.wy2]\nhi = nan\n").contains("finite"));
        assert!(err("accept_verdicts = [\"maybe\"]\n").contains("accept_verdicts"));
        assert!(err("yield = 3\n").contains("not a valid spec"));
        assert!(
            err("[parameters.wy2]\nhi = 1\ndeviation = \"ratio\"\n").contains("not a valid spec")
        );
        assert!(Spec::parse("").unwrap() == Spec::default());
    }

    /// The shipped example parses.
    #[test]
    fn the_example_spec_is_valid() {
        let text = include_str!("../spec.example.toml");
        let s = Spec::parse(text).unwrap();
        assert!(!s.parameters.is_empty());
    }
}
