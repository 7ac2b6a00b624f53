//! The paper's ±50 % test (eqs. 25 → 26 → 27), literal and with the pump re-centred.

use paragyro_core::physics::{
    OMEGA0_TABLE2_RAD_S, Physical, TABLE2, rate_dps_from_gamma, theta_from_physical,
};
use paragyro_simulator::plant::Theta;
use serde::Serialize;

use super::config::{LambdaReading, RawConfig, Segment, ZForm};
use super::records::{physical_of, settle_time, theta_rel_errors};
use super::simulate::{RawRun, simulate};

/// The paper's three parameter sets from physical parameters `p`: eq. (25) (nominal),
/// eq. (26) (every component ×1.5 except the input gains θ18, θ26) and eq. (27) (×0.5).
/// From Table 2 these are eqs. (25)–(27) with the errata of DERIVATION.md §0 (θ24 =
/// −1.77e-4, θ25 = −αy = −0.001264).
pub fn paper_sets(p: &Physical) -> [Theta; 3] {
    let (d, s) = theta_from_physical(p);
    let scaled = |f: f64| {
        let mut t = Theta { drive: d, sense: s };
        for v in &mut t.drive[..7] {
            *v *= f;
        }
        for v in &mut t.sense[..5] {
            *v *= f;
        }
        t
    };
    [scaled(1.0), scaled(1.5), scaled(0.5)]
}

/// The pump in the ±50 % test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Pump {
    /// Left at ω = √1.0265 for all three sets (the paper as written).
    Literal,
    /// Re-centred to ω = √(−θ22) of each set (keeps the drive inside its parametric band).
    Recentred,
}

/// Options of the ±50 % test.
#[derive(Clone, Copy, Debug)]
pub struct SwitchOptions {
    /// Pump policy.
    pub pump: Pump,
    /// Forgetting factor reading.
    pub lambda: LambdaReading,
    /// Length of each of the three segments, s.
    pub segment_s: f64,
    /// White displacement noise density, L0/√Hz (the paper: none).
    pub noise_density: f64,
    /// Noise seed.
    pub seed: u64,
    /// Measurement form.
    pub z_form: ZForm,
    /// Record interval, s.
    pub record_every_s: f64,
    /// Minimum RK4 steps per carrier period (128 = the plant's step).
    pub steps_per_period: usize,
}

impl SwitchOptions {
    /// Noise-free, literal Z, 0.5 s per set, 1 ms records.
    pub fn new(pump: Pump, lambda: LambdaReading) -> Self {
        Self {
            pump,
            lambda,
            segment_s: 0.5,
            noise_density: 0.0,
            seed: 1,
            z_form: ZForm::Literal,
            record_every_s: 1e-3,
            steps_per_period: 128,
        }
    }

    /// The paper's time scale: 50 ms per set (its Figs 9–14 have a time axis in ms),
    /// 0.1 ms records.
    pub fn ms_scale(pump: Pump, lambda: LambdaReading) -> Self {
        Self {
            segment_s: 0.05,
            record_every_s: 1e-4,
            ..Self::new(pump, lambda)
        }
    }
}

/// Outcome of one parameter set (segment) of a run.
#[derive(Clone, Debug, Serialize)]
pub struct SegmentSummary {
    /// "eq. 25", "eq. 26 (+50 %)", "eq. 27 (−50 %)".
    pub label: String,
    /// Start and end, s.
    pub start_s: f64,
    /// End, s.
    pub end_s: f64,
    /// Pump ω.
    pub omega: f64,
    /// Relative θ errors at the end of the segment (θ11…θ18, θ21…θ26).
    pub final_rel_err: [f64; 14],
    /// Time from the segment start after which each θ stays within 10 %.
    pub within_10pct_s: [Option<f64>; 14],
    /// … within 1 %.
    pub within_1pct_s: [Option<f64>; 14],
    /// Drive amplitude at the end of the segment, L0.
    pub drive_amp_end: f64,
    /// Sense amplitude at the end of the segment, L0.
    pub sense_amp_end: f64,
    /// Estimated and true rate at the end, °/s.
    pub rate_dps_est: f64,
    /// True rate, °/s.
    pub rate_dps_true: f64,
}

/// Summaries of the segments of a run; an error if a segment has no record at or before
/// its end (a run of [`simulate`] always has the one at t = 0).
pub fn segment_summaries(
    run: &RawRun,
    labels: &[&str],
    omega0_rad_s: f64,
) -> Result<Vec<SegmentSummary>, String> {
    let t_end = run.records.last().map_or(0.0, |r| r.t_s);
    (0..run.segment_starts_s.len())
        .map(|k| {
            let t0 = run.segment_starts_s[k];
            let t1 = run.segment_starts_s.get(k + 1).copied().unwrap_or(t_end);
            let last = run
                .records
                .iter()
                .rev()
                .find(|r| r.t_s <= t1 + 1e-12)
                .ok_or_else(|| format!("segment {k}: no record at or before {t1} s"))?;
            let (pe, pt) = physical_of(last);
            Ok(SegmentSummary {
                label: labels
                    .get(k)
                    .map_or_else(|| format!("segment {k}"), |s| s.to_string()),
                start_s: t0,
                end_s: t1,
                omega: last.omega,
                final_rel_err: theta_rel_errors(last),
                within_10pct_s: std::array::from_fn(|j| settle_time(&run.records, j, 0.1, t0, t1)),
                within_1pct_s: std::array::from_fn(|j| settle_time(&run.records, j, 0.01, t0, t1)),
                drive_amp_end: last.drive_amp,
                sense_amp_end: last.sense_amp,
                rate_dps_est: rate_dps_from_gamma(pe.gamma, omega0_rad_s),
                rate_dps_true: rate_dps_from_gamma(pt.gamma, omega0_rad_s),
            })
        })
        .collect()
}

/// Labels of the three sets.
pub const SET_LABELS: [&str; 3] = ["eq. 25", "eq. 26 (+50 %)", "eq. 27 (−50 %)"];

/// Result of the ±50 % test.
#[derive(Clone, Debug, Serialize)]
pub struct SwitchResult {
    /// "paper-raw literal" or "paper-raw variant".
    pub name: String,
    /// Pump policy.
    pub pump: Pump,
    /// λ reading.
    pub lambda: LambdaReading,
    /// λ per τ.
    pub lambda_per_tau: f64,
    /// Noise density, L0/√Hz.
    pub noise_density: f64,
    /// Length of each set, s.
    pub segment_s: f64,
    /// Minimum RK4 steps per carrier period.
    pub steps_per_period: usize,
    /// The run (not serialised; the report writes its [`RunNumbers`](super::RunNumbers)).
    #[serde(skip)]
    pub run: RawRun,
    /// One summary per set.
    pub segments: Vec<SegmentSummary>,
    /// Drive amplitude at the end of the nominal set, L0.
    pub drive_amp_nominal: f64,
    /// Time after the +50 % switch at which the drive amplitude first falls below 1 % of
    /// `drive_amp_nominal`, s.
    pub drive_below_1pct_after_s: Option<f64>,
    /// Smallest drive amplitude in the last 10 % of each of the +50 % and −50 % sets,
    /// relative to `drive_amp_nominal`.
    pub drive_amp_rel_end: [f64; 2],
}

/// The paper's ±50 % test (sets of [`paper_sets`] from Table 2, `segment_s` each) on the
/// raw estimator: `Pump::Literal` is "paper-raw literal", `Pump::Recentred` is
/// "paper-raw variant". The plant starts from X(0) = 0.01 at rest.
pub fn paper_switch(opts: &SwitchOptions) -> Result<SwitchResult, String> {
    let w0 = OMEGA0_TABLE2_RAD_S;
    let sets = paper_sets(&TABLE2);
    let lit = 1.0265f64.sqrt();
    let segs: Vec<Segment> = sets
        .iter()
        .map(|th| Segment {
            duration_s: opts.segment_s,
            theta: *th,
            omega: match opts.pump {
                Pump::Literal => lit,
                Pump::Recentred => (-th.sense[1]).sqrt(),
            },
        })
        .collect();
    let cfg = RawConfig {
        omega0_rad_s: w0,
        noise_density: opts.noise_density,
        seed: opts.seed,
        lambda_per_tau: opts.lambda.per_tau(w0),
        z_form: opts.z_form,
        record_every_s: opts.record_every_s,
        steps_per_period: opts.steps_per_period,
        ..RawConfig::default()
    };
    let run = simulate(&cfg, &segs)?;
    let segments = segment_summaries(&run, &SET_LABELS, w0)?;
    let nominal = segments[0].drive_amp_end;
    let t_switch = run.segment_starts_s[1];
    let below = run
        .records
        .iter()
        .find(|r| r.t_s > t_switch && r.drive_amp < 0.01 * nominal)
        .map(|r| r.t_s - t_switch);
    let tail_min = |k: usize| {
        let (a, b) = (segments[k].start_s, segments[k].end_s);
        let from = b - 0.1 * (b - a);
        run.records
            .iter()
            .filter(|r| r.t_s > from && r.t_s <= b + 1e-12)
            .map(|r| r.drive_amp)
            .fold(f64::INFINITY, f64::min)
            / nominal
    };
    Ok(SwitchResult {
        name: match opts.pump {
            Pump::Literal => "paper-raw literal".into(),
            Pump::Recentred => "paper-raw variant".into(),
        },
        pump: opts.pump,
        lambda: opts.lambda,
        lambda_per_tau: cfg.lambda_per_tau,
        noise_density: opts.noise_density,
        segment_s: opts.segment_s,
        steps_per_period: opts.steps_per_period,
        drive_amp_rel_end: [tail_min(1), tail_min(2)],
        run,
        segments,
        drive_amp_nominal: nominal,
        drive_below_1pct_after_s: below,
    })
}
