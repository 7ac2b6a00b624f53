//! Stage 1b, calibration (the parameter face of the gap): the device's parameters
//! identified from the record by batch least squares of the 14 θ on the rows of the fit
//! span (cluster-robust covariance, jackknife over the fit blocks), mapped to the physical
//! parameters with their uncertainties, compared with the model parameter by parameter,
//! and the pattern of the deviations matched against the parameter-face effects, with
//! plain manufacturing tolerance (independent deviations) as the null hypothesis.
//!
//! The θ are linear in the rows, so one fit on the gap `y = rows(record) − rows(simulator)`
//! gives `Δθ`; the simulator is then re-run with the calibrated parameters (its trajectory
//! now follows the record's, so the rows' own approximations cancel again) and the fit on
//! the new gap refines `Δθ` and gives the reported values and covariance.

use paragyro_core::Physical;
use paragyro_core::physics::{physical_from_theta, rate_dps_from_gamma, theta_from_physical};
use paragyro_simulator::effects::ES_C3;
use serde::{Deserialize, Serialize};

use super::lsq::Bank;
use super::rows::{Rows, Spans};
use super::{Model, NR, T_SIG};

/// Names of the calibrated parameters, in report order ([`Physical`]'s fields).
pub const PARAM_NAMES: [&str; 14] = [
    "mu_x", "mu_y", "mu_xy", "wx2", "wy2", "wxy2", "alpha_x", "alpha_y", "beta1", "beta3", "gamma",
    "gamma_p", "c_ax", "c_ay",
];

/// A deviation is reported as significant at |t| ≥ this.
pub const T_PARAM: f64 = 3.0;

fn to_arr(p: &Physical) -> [f64; 14] {
    let a = p.as_array();
    let mut v = [0.0; 14];
    v[..12].copy_from_slice(&a);
    v[12] = p.c_ax;
    v[13] = p.c_ay;
    v
}

fn from_arr(v: &[f64; 14]) -> Physical {
    let mut a = [0.0; 12];
    a.copy_from_slice(&v[..12]);
    let mut p = Physical::from_array(a);
    p.c_ax = v[12];
    p.c_ay = v[13];
    p
}

fn theta_arr(p: &Physical) -> [f64; 14] {
    let (d, s) = theta_from_physical(p);
    let mut v = [0.0; 14];
    v[..8].copy_from_slice(&d);
    v[8..].copy_from_slice(&s);
    v
}

fn phys_of_theta(t: &[f64; 14]) -> Physical {
    let mut d = [0.0; 8];
    let mut s = [0.0; 6];
    d.copy_from_slice(&t[..8]);
    s.copy_from_slice(&t[8..]);
    physical_from_theta(&d, &s)
}

/// One parameter of the device against the model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamDeviation {
    /// The parameter ([`PARAM_NAMES`]).
    pub name: String,
    /// The model's value (γ: the rate table's mean when the record has one).
    pub model: f64,
    /// The calibrated value.
    pub device: f64,
    /// Its 1σ (cluster-robust, `lsq::Bank::fit`).
    pub sigma: f64,
    /// `(device − model)/|model|` and its 1σ, when the model's value is not 0.
    pub relative: Option<f64>,
    pub relative_sigma: Option<f64>,
    /// `(device − model)/σ`.
    pub t: f64,
}

/// A hypothesis of the parameter face.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FaceHypothesis {
    /// `tolerance` (the null hypothesis) or a library effect's name.
    pub name: String,
    /// `null`, `named`, `consistent`, `rejected`, `untestable` or `structural` (tested as a
    /// column of the structural face, see the ranking).
    pub status: String,
    /// The size it implies, and its 1σ.
    pub size: Option<f64>,
    pub sigma: Option<f64>,
    /// Why, and what would separate it.
    pub detail: String,
}

/// The parameter face of the gap (report.json's `parameter_face`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParameterFace {
    /// The device's parameters against the model's.
    pub parameters: Vec<ParamDeviation>,
    /// The hypotheses, the null first.
    pub hypotheses: Vec<FaceHypothesis>,
    /// The rate the calibrated γ implies against the rate table's, °/s (with a table).
    pub rate_offset_dps: Option<f64>,
    /// The record's noise against the model's (ν², energy ratio; 1 = 1 pm/√Hz), from
    /// the sample-to-sample differences of the calibrated re-simulation's error.
    pub noise_energy_ratio: f64,
    /// Simulator passes of the calibration.
    pub resimulations: usize,
}

impl ParameterFace {
    /// The calibrated parameter `name` (`wy2`, `mu_x`, … as in [`ParamDeviation::name`]).
    pub fn parameter(&self, name: &str) -> Option<&ParamDeviation> {
        self.parameters.iter().find(|p| p.name == name)
    }

    /// The effect the face names (its first hypothesis whose status is `named`:
    /// anisodamping against a rate table), if any.
    pub(crate) fn named_effect(&self) -> Option<paragyro_simulator::effects::Effect> {
        self.hypotheses
            .iter()
            .find(|h| h.status == "named")
            .and_then(|h| h.name.parse().ok())
    }
}

/// The θ fit on a gap: `Δθ` (14) and its covariance (14 × 14, row-major).
pub(crate) struct ThetaFit {
    pub dtheta: [f64; 14],
    pub cov: Vec<f64>,
}

impl ThetaFit {
    /// The refinement `fit` plus the θ part of a fit whose first 14 columns are the θ (the
    /// baseline) and the rest an effect's: `Δθ` and its covariance with the effect fitted
    /// jointly.
    pub(crate) fn joint(fit: &ThetaFit, f: &super::lsq::Fit) -> ThetaFit {
        let p = f.beta.len();
        let mut dtheta = fit.dtheta;
        for (d, b) in dtheta.iter_mut().zip(&f.beta) {
            *d += b;
        }
        let mut cov = vec![0.0; 14 * 14];
        for i in 0..14 {
            for j in 0..14 {
                cov[i * 14 + j] = f.cov[i * p + j];
            }
        }
        ThetaFit { dtheta, cov }
    }
}

/// Batch least squares of the 14 θ columns of the record's rows on the gap `rows.y`,
/// over the fit span (cluster-robust covariance over its blocks, [`super::lsq::Bank::fit`]).
pub(crate) fn fit_theta(rows: &Rows, spans: &Spans) -> ThetaFit {
    let cols = rows.theta_columns();
    let refs: Vec<&[[f64; NR]]> = cols.iter().map(|c| c.as_slice()).collect();
    let bank = Bank::build(
        &refs,
        &rows.y,
        &rows.usable,
        &spans.fit_blocks,
        spans.hold.clone(),
    );
    let idx: Vec<usize> = (0..14).collect();
    let f = bank.fit(&idx);
    let mut dtheta = [0.0; 14];
    dtheta.copy_from_slice(&f.beta);
    ThetaFit { dtheta, cov: f.cov }
}

/// The calibrated model: the θ the rows were simulated with (the model's, γ at the rows'
/// linearisation rate plus the model's offset) plus `Δθ`.
pub(crate) fn calibrated_model(model: &Model, rows: &Rows, fit: &ThetaFit, label: &str) -> Model {
    let th = device_theta(model, rows, fit);
    let phys = phys_of_theta(&th);
    let gamma_lin = rows.gamma_nom;
    Model {
        phys,
        source: label.into(),
        gamma_offset: if rows.rate_ref.is_some() {
            phys.gamma - gamma_lin
        } else {
            0.0
        },
    }
}

/// Why `model` cannot be handed to the core or the simulator (a parameter not finite, or
/// not positive where the physics needs it: the core's own checks of its nominal
/// parameters, [`paragyro_core::Config::validate`]), or `None` when it can. A calibration
/// on a record far from the model (or on too little excitation) can estimate such a model.
pub(crate) fn unphysical(model: &Model) -> Option<String> {
    if !model.gamma_offset.is_finite() {
        return Some(format!("gamma_offset = {}", model.gamma_offset));
    }
    let mut cfg = paragyro_core::Config::table2();
    cfg.nominal = model.phys;
    cfg.validate().err().map(|e| {
        let p = &model.phys;
        format!(
            "{e} (mu_x = {:.3e}, mu_y = {:.3e}, wx2 = {:.4}, wy2 = {:.4}, beta1 = {:.3e})",
            p.mu_x, p.mu_y, p.wx2, p.wy2, p.beta1
        )
    })
}

/// θ of the device: the simulated model's θ (at the rows' rate) plus `Δθ`.
fn device_theta(model: &Model, rows: &Rows, fit: &ThetaFit) -> [f64; 14] {
    let mut p = model.phys;
    p.gamma = match rows.rate_ref {
        Some(_) => rows.gamma_nom + model.gamma_offset,
        None => rows.gamma_sim.unwrap_or(p.gamma),
    };
    let mut th = theta_arr(&p);
    for (t, d) in th.iter_mut().zip(&fit.dtheta) {
        *t += d;
    }
    th
}

/// The parameter face: the device's parameters (the calibrated model plus the last fit)
/// against the configured model's, and the hypotheses.
pub(crate) fn face(
    configured: &Model,
    calibrated: &Model,
    rows: &Rows,
    fit: &ThetaFit,
    noise_energy_ratio: f64,
    resimulations: usize,
) -> (ParameterFace, Physical) {
    let th = device_theta(calibrated, rows, fit);
    let dev = to_arr(&phys_of_theta(&th));
    // J = ∂phys/∂θ (numerically; linear but for γ²)
    let mut jac = [[0.0; 14]; 14];
    for j in 0..14 {
        let h = 1e-7 * th[j].abs().max(1e-6);
        let (mut a, mut b) = (th, th);
        a[j] += h;
        b[j] -= h;
        let (pa, pb) = (to_arr(&phys_of_theta(&a)), to_arr(&phys_of_theta(&b)));
        for i in 0..14 {
            jac[i][j] = (pa[i] - pb[i]) / (2.0 * h);
        }
    }
    let cov_p = |i: usize, k: usize| -> f64 {
        let mut v = 0.0;
        for a in 0..14 {
            for b in 0..14 {
                v += jac[i][a] * fit.cov[a * 14 + b] * jac[k][b];
            }
        }
        v
    };
    let mut model = to_arr(&configured.phys);
    model[10] = match rows.rate_ref {
        Some(_) => rows.gamma_nom,
        None => configured.phys.gamma,
    };
    let parameters: Vec<ParamDeviation> = (0..14)
        .map(|i| {
            let sigma = cov_p(i, i).max(0.0).sqrt();
            let d = dev[i] - model[i];
            let rel = (model[i] != 0.0).then(|| d / model[i].abs());
            ParamDeviation {
                name: PARAM_NAMES[i].into(),
                model: model[i],
                device: dev[i],
                sigma,
                relative: rel,
                relative_sigma: rel.map(|_| sigma / model[i].abs()),
                t: if sigma > 0.0 { d / sigma } else { 0.0 },
            }
        })
        .collect();
    let hypotheses = hypotheses(&parameters, rows, &|i, k| cov_p(i, k));
    let rate_offset_dps = rows
        .rate_ref
        .is_some()
        .then(|| rate_dps_from_gamma(dev[10] - rows.gamma_nom, rows.omega0));
    (
        ParameterFace {
            parameters,
            hypotheses,
            rate_offset_dps,
            noise_energy_ratio,
            resimulations,
        },
        from_arr(&dev),
    )
}

/// A deviation as "wy2 +0.100 % ± 0.002 %" (relative) or "gamma_p +1.2e-7 ± 3e-9".
pub fn describe(p: &ParamDeviation) -> String {
    match (p.relative, p.relative_sigma) {
        (Some(r), Some(s)) => format!("{} {}", p.name, percent_pm(r, s)),
        _ => format!("{} {:+.3e} ± {:.1e}", p.name, p.device - p.model, p.sigma),
    }
}

/// A relative deviation and its σ in percent, with the decimals that show σ to two
/// significant digits (at least 3, at most 9): `+0.0973871 % ± 0.0000011 %`, not
/// `+0.097 % ± 0.000 %`.
pub fn percent_pm(rel: f64, rel_sigma: f64) -> String {
    let (r, s) = (100.0 * rel, 100.0 * rel_sigma);
    let dec = if s > 0.0 && s.is_finite() {
        (1.0 - s.log10().floor()).clamp(3.0, 9.0) as usize
    } else {
        3
    };
    format!("{r:+.dec$} % ± {s:.dec$} %")
}

/// `v` with the significant digits its σ warrants (σ to two digits; 4 to 10 digits),
/// fixed-point between 1e-2 and 1e5, else scientific.
pub fn value_to_sigma(v: f64, sigma: f64) -> String {
    if !v.is_finite() || v == 0.0 {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor();
    let digits = if sigma > 0.0 && sigma.is_finite() {
        (mag - sigma.log10().floor() + 2.0).clamp(4.0, 10.0)
    } else {
        4.0
    };
    if (1e-2..1e5).contains(&v.abs()) {
        let dec = (digits - 1.0 - mag).max(0.0) as usize;
        format!("{v:.dec$}")
    } else {
        let dec = (digits - 1.0) as usize;
        format!("{v:.dec$e}")
    }
}

const I_WY2: usize = 4;
const I_ALPHA_Y: usize = 7;
const I_GAMMA: usize = 10;

fn hypotheses(
    ps: &[ParamDeviation],
    rows: &Rows,
    cov: &dyn Fn(usize, usize) -> f64,
) -> Vec<FaceHypothesis> {
    let sig: Vec<String> = ps
        .iter()
        .filter(|p| p.t.abs() >= T_PARAM)
        .map(describe)
        .collect();
    let mut h = vec![FaceHypothesis {
        name: "tolerance".into(),
        status: "null".into(),
        size: None,
        sigma: None,
        detail: if sig.is_empty() {
            "no parameter departs from the model by 3σ or more".into()
        } else {
            format!(
                "independent deviations (significant at 3σ: {}); the null hypothesis unless a pattern below says otherwise",
                sig.join(", ")
            )
        },
    }];
    // electrostatic softening (a fixed bias): Δωy² = κ and Δαy = c3·κ together
    let (dw, da) = (
        ps[I_WY2].device - ps[I_WY2].model,
        ps[I_ALPHA_Y].device - ps[I_ALPHA_Y].model,
    );
    let (vw, va, cwa) = (
        cov(I_WY2, I_WY2),
        cov(I_ALPHA_Y, I_ALPHA_Y),
        cov(I_WY2, I_ALPHA_Y),
    );
    // κ from both (generalised least squares on the direction (1, c3))
    let det = vw * va - cwa * cwa;
    let (kappa, ksig, chi2) = if det > 0.0 {
        let (iw, ia, iwa) = (va / det, vw / det, -cwa / det);
        let info = iw + 2.0 * iwa * ES_C3 + ia * ES_C3 * ES_C3;
        let k = (iw * dw + iwa * (da + ES_C3 * dw) + ia * ES_C3 * da) / info;
        let (rw, ra) = (dw - k, da - ES_C3 * k);
        (
            k,
            1.0 / info.sqrt(),
            iw * rw * rw + 2.0 * iwa * rw * ra + ia * ra * ra,
        )
    } else {
        (dw, vw.max(0.0).sqrt(), 0.0)
    };
    let es_status = if (kappa / ksig).abs() < T_SIG {
        "consistent"
    } else if chi2 > 9.0 {
        "rejected"
    } else {
        "consistent"
    };
    h.push(FaceHypothesis {
        name: "electrostatic_softening".into(),
        status: es_status.into(),
        size: Some(kappa),
        sigma: Some(ksig),
        detail: format!(
            "a fixed bias moves wy2 by κ and alpha_y by {ES_C3:.3}·κ together: κ = {kappa:.3e} ± {ksig:.1e}, pattern χ² = {chi2:.1} (1 dof){}; independent tolerances of wy2 and alpha_y can take the same values, so this record cannot separate it from tolerance: a sense-bias step (or a pump-amplitude step when its electrodes carry the pump, tested on the structural face) would",
            if es_status == "rejected" {
                ": the deviations do not follow the pattern"
            } else {
                ""
            }
        ),
    });
    // anisodamping: (θ14 − θ24)/4 against a rate table
    match rows.rate_ref {
        Some(_) => {
            let p = &ps[I_GAMMA];
            let d = -4.0 * (p.device - p.model);
            let s = 4.0 * p.sigma;
            let named = s > 0.0 && (d / s).abs() >= T_SIG;
            h.push(FaceHypothesis {
                name: "anisodamping".into(),
                status: if named { "named" } else { "consistent" }.into(),
                size: Some(d),
                sigma: Some(s),
                detail: format!(
                    "the calibrated (θ14 − θ24)/4 departs from the rate table's γ by {:+.3e} ± {:.1e} ({:+.2} °/s): d = −4·Δγ = {d:.3e} ± {s:.1e}{}; manufacturing tolerance of the model's parameters cannot move it (μxy moves θ14 + θ24); a rate-table scale error would move it alike, and so would a delay of the sense pick-off (a sense-only coupling ωxy²·delay of X′, which with a μxy tolerance is this pattern): this record cannot separate them; a check of the rate table separates the first, the sense front end's phase measured with an electrical test signal the second",
                    p.device - p.model,
                    p.sigma,
                    rate_dps_from_gamma(p.device - p.model, rows.omega0),
                    if named {
                        " — significant"
                    } else {
                        ""
                    }
                ),
            });
        }
        None => h.push(FaceHypothesis {
            name: "anisodamping".into(),
            status: "untestable".into(),
            size: None,
            sigma: None,
            detail: "without a rate reference it is a rate offset: record on a rate table or with zero-rate segments".into(),
        }),
    }
    let dt = rows.temps.as_ref().map(|t| {
        t.iter().cloned().fold(f64::MIN, f64::max) - t.iter().cloned().fold(f64::MAX, f64::min)
    });
    h.push(FaceHypothesis {
        name: "thermal_drift".into(),
        status: match dt {
            Some(d) if d >= 0.5 => "structural",
            _ => "untestable",
        }
        .into(),
        size: None,
        sigma: None,
        detail: match dt {
            Some(d) if d >= 0.5 => format!(
                "wx2 and wy2 moving together with temp_c (ΔT = {d:.2} K): tested as a column of the structural face (θ12, θ22 × ΔT); a constant temperature offset is a tolerance"
            ),
            _ => "the die temperature does not move by 0.5 K: a temperature step would separate it from tolerance".into(),
        },
    });
    h
}

#[cfg(test)]
mod tests {
    use super::{percent_pm, value_to_sigma};

    #[test]
    fn a_deviation_shows_its_sigma_to_two_digits() {
        // ωy² +0.1 % found to 1e-8 (docs/diagnosis.md, example 1): not "± 0.000 %"
        assert_eq!(
            percent_pm(9.73871e-4, 1.12e-8),
            "+0.0973871 % ± 0.0000011 %"
        );
        assert_eq!(percent_pm(0.20012, 3.8e-4), "+20.012 % ± 0.038 %");
        // at least three decimals, at most nine, and a σ that is not a number
        assert_eq!(percent_pm(0.05, 0.2), "+5.000 % ± 20.000 %");
        assert_eq!(percent_pm(1e-3, 1e-14), "+0.100000000 % ± 0.000000000 %");
        assert_eq!(percent_pm(1e-3, f64::NAN), "+0.100 % ± NaN %");
    }

    #[test]
    fn a_value_shows_the_digits_its_sigma_warrants() {
        assert_eq!(value_to_sigma(1.027500006, 1.15e-8), "1.027500006");
        assert_eq!(value_to_sigma(1.0265, 1.15e-8), "1.026500000");
        assert_eq!(value_to_sigma(1.0600216e-3, 5.3e-8), "1.060022e-3");
        assert_eq!(value_to_sigma(0.0226002, 2.7e-7), "0.02260020");
        assert_eq!(value_to_sigma(6.0852e-5, 6.6e-8), "6.0852e-5");
        assert_eq!(value_to_sigma(6.0852e-5, 6.6e-7), "6.085e-5");
        assert_eq!(value_to_sigma(0.0, 1.0), "0");
        // σ not positive: four digits
        assert_eq!(value_to_sigma(2.5204, 0.0), "2.520");
    }
}

#[cfg(test)]
mod unphysical_tests {
    use super::unphysical;
    use crate::diagnose::Model;

    /// Issue 31: a calibration on a rate-table reversal estimated μx ≤ 0, and the core
    /// refused the model ("nominal.mu_x: must be finite and > 0") with no report written.
    /// The check names it before the model reaches the core.
    #[test]
    fn a_model_the_core_would_refuse_is_named() {
        assert_eq!(unphysical(&Model::table2()), None);
        let mut m = Model::table2();
        m.phys.mu_x = -2.0e-4;
        let why = unphysical(&m).expect("μx < 0 is not physical");
        assert!(why.contains("nominal.mu_x"), "{why}");
        let mut m = Model::table2();
        m.phys.wy2 = f64::NAN;
        assert!(unphysical(&m).unwrap().contains("nominal.wy2"));
        let mut m = Model::table2();
        m.phys.gamma = f64::INFINITY;
        assert!(unphysical(&m).is_some());
        let mut m = Model::table2();
        m.gamma_offset = f64::NAN;
        assert!(unphysical(&m).unwrap().contains("gamma_offset"));
    }
}
