//! The fault campaign: every [`FaultClass`] injected into the closed loop of the
//! simulated gyro and the **f32** core, at seeded random times and sizes, and scored
//! (`paragyro-sim faults`, host-sim/docs/reliability.md "Fault campaign").
//!
//! Each class runs the built-in `identify` scenario (start-up from a design 3–10 % off,
//! pump dither from 1 s, retune on) for `ticks` samples: `warmup` clean ticks, then one
//! episode per `slot` ticks at a random offset in the slot's first fifth, with a random
//! length and size in the class's range ([`FaultClass`]). The faults enter through the
//! runner's [`crate::runner::LoopHooks`]: a value in the sample, a sample never
//! delivered, the truth of the plant, or the pump reaching it. The injected faults are at
//! the sample level: an SPI CRC error or a missing DRDY is what the firmware makes of it
//! (NaN channels, firmware/src/app.rs), not a frame through the drivers.
//!
//! Per class ([`ClassReport`]): panics of `step` (caught), ticks with a non-finite
//! output, flagged samples whose step changed θ̂ (the estimate must be held), false
//! flags, the fraction of episodes flagged and recovered, the recovery time and the
//! ω̂y² and rate errors at recovery. The classes run in parallel ([`crate::par`]: order
//! kept, a panic is an error).

mod class;
mod inject;
pub mod soak;
#[cfg(test)]
mod tests;
pub mod warm;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

pub use class::{Episode, FaultClass, Schedule, plan};
pub use inject::{
    EpisodeScore, FLAG_GRACE, Injector, RECOVERY_HOLD, RECOVERY_RATE_FLOOR_DPS, RECOVERY_WY2_FLOOR,
};

use crate::runner::{Device, closed_loop_hooked, core_config};
use crate::scenario::Scenario;

/// Settings of a campaign.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignOptions {
    /// Ticks (500 Hz samples) per class.
    pub ticks: u64,
    /// Seed of the episodes (times, lengths, channels, sizes) and of the plant noise.
    pub seed: u64,
    /// Clean ticks before the first episode slot.
    pub warmup: u64,
    /// Ticks per episode slot.
    pub slot: u64,
    /// The classes to run (all by default).
    pub classes: Vec<FaultClass>,
}

impl CampaignOptions {
    /// `ticks` per class, every class, 10 s warm-up, 10 s slots.
    pub fn new(ticks: u64, seed: u64) -> Self {
        CampaignOptions {
            ticks,
            seed,
            warmup: 5000,
            slot: 5000,
            classes: FaultClass::ALL.to_vec(),
        }
    }
}

/// The score of one class (one entry of `faults.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassReport {
    /// Class name ([`FaultClass::name`]).
    pub class: String,
    /// Ticks run (500 Hz samples of the f32 core).
    pub ticks: u64,
    /// Episodes injected.
    pub episodes: usize,
    /// Steps that panicked (caught with `catch_unwind`).
    pub panics: u64,
    /// Ticks with a non-finite pump command, θ̂, ω̂y² or rate.
    pub non_finite_outputs: u64,
    /// Samples flagged as bad whose step changed θ̂ (must be 0: the estimate is held).
    pub held_violations: u64,
    /// The core should flag this class ([`FaultClass::flag_expected`]).
    pub flag_expected: bool,
    /// Fraction of episodes with a flag (bad input, change detected, drive lock lost)
    /// between the start and 1 s after the end.
    pub flagged: f64,
    /// Flag events after the warm-up outside every episode and its recovery (the sum
    /// of the three below).
    pub false_flags: u64,
    /// … of them bad-input events.
    pub false_bad_input: u64,
    /// … change-detector alarms (covariance resets).
    pub false_changes: u64,
    /// … drive-lock losses.
    pub false_lock_losses: u64,
    /// Fraction of episodes recovered before the next one ([`EpisodeScore`]).
    pub recovered: f64,
    /// Recovery time from the end of the episode, s: median and 95th percentile over
    /// the recovered episodes (`null` if none recovered).
    pub recovery_s_p50: Option<f64>,
    /// 95th percentile of the recovery time, s.
    pub recovery_s_p95: Option<f64>,
    /// Relative ω̂y² error on the tick before the episodes (95th percentile).
    pub wy2_rel_err_before_p95: Option<f64>,
    /// Rate error on the tick before the episodes, °/s (95th percentile).
    pub rate_err_dps_before_p95: Option<f64>,
    /// Relative ω̂y² error at recovery (after its 1 s hold; 95th percentile).
    pub wy2_rel_err_after_p95: Option<f64>,
    /// Rate error at recovery, °/s (95th percentile).
    pub rate_err_dps_after_p95: Option<f64>,
    /// The core's bad-sample counter at the end.
    pub bad_samples: u32,
    /// Covariance resets by the change detector (drive + sense).
    pub resets: u32,
    /// Change alarms read as a drift (the drift column re-opened instead of a reset;
    /// `Counters::drift_alarms`).
    pub drift_alarms: u32,
}

/// `faults.json`: the campaign's settings and one entry per class.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FaultsReport {
    /// The scenario every class runs.
    pub scenario: String,
    /// Core precision (always f32: what the chip runs).
    pub precision: String,
    /// The settings.
    pub options: CampaignOptions,
    /// One entry per class, in the options' order.
    pub classes: Vec<ClassReport>,
}

impl FaultsReport {
    /// The campaign's table (Markdown), as in host-sim/docs/reliability.md "Fault campaign".
    pub fn table_md(&self) -> String {
        let f = |v: Option<f64>, prec: usize| match v {
            Some(x) => format!("{x:.prec$}"),
            None => "–".into(),
        };
        let mut t = String::from(
            "| class | ticks | episodes | panics | non-finite | held viol. | flagged | false flags (bad/change/lock) | recovered | recovery p50 / p95, s | ω̂y² err after (p95) | rate err after (p95), °/s |\n\
             |---|---|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for c in &self.classes {
            let flagged = if c.flag_expected {
                format!("{:.0} %", 100.0 * c.flagged)
            } else {
                format!("({:.0} %, not expected)", 100.0 * c.flagged)
            };
            t.push_str(&format!(
                "| {} | {} | {} | {} | {} | {} | {} | {} ({}/{}/{}) | {:.0} % | {} / {} | {} | {} |\n",
                c.class,
                c.ticks,
                c.episodes,
                c.panics,
                c.non_finite_outputs,
                c.held_violations,
                flagged,
                c.false_flags,
                c.false_bad_input,
                c.false_changes,
                c.false_lock_losses,
                100.0 * c.recovered,
                f(c.recovery_s_p50, 2),
                f(c.recovery_s_p95, 2),
                c.wy2_rel_err_after_p95
                    .map_or("–".into(), |v| format!("{v:.1e}")),
                f(c.rate_err_dps_after_p95, 2),
            ));
        }
        t
    }
}

/// The `q` quantile (nearest rank) of `v` (`None` if empty).
fn quantile(v: &mut [f64], q: f64) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let i = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1;
    Some(v[i])
}

/// The scenario a campaign runs: the built-in `identify`, `ticks` samples long.
pub fn campaign_scenario(ticks: u64) -> Result<Scenario> {
    let mut sc = Scenario::builtin("identify").context("the built-in 'identify' is missing")?;
    let cfg = core_config(&sc);
    // the loop steps ticks 0..=n
    sc.duration_s = (ticks.max(2) - 1) as f64 / cfg.fs_hz;
    Ok(sc)
}

/// Runs one class; `progress` gets the fraction done.
pub fn run_class(
    class: FaultClass,
    opts: &CampaignOptions,
    progress: &(dyn Fn(FaultClass, f64) + Sync),
) -> Result<ClassReport> {
    let sc = campaign_scenario(opts.ticks)?;
    let cfg = core_config(&sc);
    let mut est = cfg
        .build::<f32>()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let sched = Schedule {
        ticks: opts.ticks,
        warmup: opts.warmup,
        slot: opts.slot,
    };
    let episodes = plan(class, &sched, opts.seed);
    let mut inj = Injector::new(
        class,
        episodes.clone(),
        opts.warmup,
        sc.omega0_rad_s(),
        sc.sim.f0_hz,
    );
    let every = (opts.ticks / 4).max(1);
    closed_loop_hooked(
        &sc,
        opts.seed,
        &Device::default(),
        &mut est,
        &mut inj,
        |_| {},
        |ls| {
            if ls.k > 0 && ls.k % every == 0 {
                progress(class, ls.k as f64 / opts.ticks as f64);
            }
        },
    )
    .with_context(|| format!("fault class {}", class.name()))?;
    let n = episodes.len();
    let rec: Vec<(&Episode, &EpisodeScore)> = episodes
        .iter()
        .zip(&inj.scores)
        .filter(|(_, s)| s.recovered_at.is_some())
        .collect();
    let fs = cfg.fs_hz;
    let mut rec_s: Vec<f64> = rec
        .iter()
        .map(|(e, s)| (s.recovered_at.unwrap_or(0) - e.end()) as f64 / fs)
        .collect();
    let mut before: Vec<f64> = inj.scores.iter().map(|s| s.wy2_err_before).collect();
    let mut rate_before: Vec<f64> = inj.scores.iter().map(|s| s.rate_err_before_dps).collect();
    let mut after: Vec<f64> = rec.iter().map(|(_, s)| s.wy2_err_after).collect();
    let mut rate: Vec<f64> = rec.iter().map(|(_, s)| s.rate_err_after_dps).collect();
    let frac = |m: usize| if n == 0 { 0.0 } else { m as f64 / n as f64 };
    let counters = est.counters();
    Ok(ClassReport {
        class: class.name().into(),
        ticks: opts.ticks,
        episodes: n,
        panics: inj.panics,
        non_finite_outputs: inj.non_finite_outputs,
        held_violations: inj.held_violations,
        flag_expected: class.flag_expected(),
        flagged: frac(inj.scores.iter().filter(|s| s.flagged).count()),
        false_flags: inj.false_flags.iter().sum(),
        false_bad_input: inj.false_flags[0],
        false_changes: inj.false_flags[1],
        false_lock_losses: inj.false_flags[2],
        recovered: frac(rec.len()),
        recovery_s_p50: quantile(&mut rec_s.clone(), 0.5),
        recovery_s_p95: quantile(&mut rec_s, 0.95),
        wy2_rel_err_before_p95: quantile(&mut before, 0.95),
        rate_err_dps_before_p95: quantile(&mut rate_before, 0.95),
        wy2_rel_err_after_p95: quantile(&mut after, 0.95),
        rate_err_dps_after_p95: quantile(&mut rate, 0.95),
        bad_samples: counters.bad_samples,
        resets: counters.resets_drive.saturating_add(counters.resets_sense),
        drift_alarms: counters.drift_alarms,
    })
}

/// Runs the campaign: every class of `opts` in parallel (order kept; a failed or
/// panicking class is an error naming it).
pub fn run_campaign(
    opts: &CampaignOptions,
    progress: &(dyn Fn(FaultClass, f64) + Sync),
) -> Result<FaultsReport> {
    anyhow::ensure!(
        opts.ticks >= opts.warmup + opts.slot,
        "--ticks {} is shorter than the warm-up ({}) plus one slot ({})",
        opts.ticks,
        opts.warmup,
        opts.slot
    );
    anyhow::ensure!(opts.slot >= 100, "the slot must be at least 100 ticks");
    let classes = crate::par::try_map(
        &opts.classes,
        |c| format!("fault class {}", c.name()),
        |c| {
            let r = run_class(*c, opts, progress)?;
            progress(*c, 1.0);
            Ok(r)
        },
    )?;
    Ok(FaultsReport {
        scenario: "identify".into(),
        precision: "f32".into(),
        options: opts.clone(),
        classes,
    })
}
