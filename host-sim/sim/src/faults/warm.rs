//! Warm start against cold start, measured on the simulated gyro (host-sim/docs/reliability.md "Warm start").
//!
//! A cold boot runs the built-in `identify` scenario from the design values (3–10 % off
//! the plant) with the f32 core; its snapshot at the end ([`paragyro_core::persist`]) is
//! encoded, decoded and given to a second boot of the same device (plant again from
//! rest, another noise seed), which starts warm. Both boots are timed the same way:
//!
//! * **settled**: the first tick whose health says settled (the estimator's own verdict,
//!   what the retune supervisor waits for);
//! * **converged**: from boot until the relative ω̂y² error stays within
//!   [`super::RECOVERY_WY2_FLOOR`] and the rate error within
//!   [`super::RECOVERY_RATE_FLOOR_DPS`] to the end of the run (the fault campaign's
//!   floors).

use anyhow::{Context, Result};
use paragyro_core::persist::{Snapshot, Start};
use paragyro_core::{Estimator, Real};
use serde::{Deserialize, Serialize};

use super::{RECOVERY_RATE_FLOOR_DPS, RECOVERY_WY2_FLOOR};
use crate::runner::{closed_loop, core_config};
use crate::scenario::Scenario;

/// The timings of one boot.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BootTimes {
    /// First settled tick, s from boot (`None`: never).
    pub settled_s: Option<f64>,
    /// From boot until ω̂y² and the rate stay within the floors, s (`None`: not by the
    /// end).
    pub converged_s: Option<f64>,
}

/// Cold against warm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WarmReport {
    /// Simulated seconds per boot.
    pub duration_s: f64,
    /// The compared boots run with the pump dither.
    pub dither: bool,
    /// The cold boot.
    pub cold: BootTimes,
    /// The warm boot.
    pub warm: BootTimes,
}

impl WarmReport {
    /// warm / cold of the settle time (`None` if either never settled).
    pub fn settled_ratio(&self) -> Option<f64> {
        Some(self.warm.settled_s? / self.cold.settled_s?)
    }
    /// warm / cold of the convergence time.
    pub fn converged_ratio(&self) -> Option<f64> {
        Some(self.warm.converged_s? / self.cold.converged_s?)
    }
}

/// One boot of `sc` with `est`; its timings.
fn boot<T: Real>(sc: &Scenario, seed: u64, est: &mut Estimator<T>) -> Result<BootTimes> {
    let fs = est.config().fs_hz;
    let mut settled = None;
    let mut last_bad = None;
    let mut n = 0u64;
    closed_loop(
        sc,
        seed,
        est,
        |_| {},
        |ls| {
            n = ls.k + 1;
            if settled.is_none() && ls.out.health.settled {
                settled = Some(ls.k);
            }
            let wy2 = ls.est.wy2();
            let err = (wy2 - ls.plant.phys[4]).abs() / ls.plant.phys[4].abs();
            let rate_err = (ls.est.rate_dps() - ls.plant.rate_dps).abs();
            let ok = err <= RECOVERY_WY2_FLOOR && rate_err <= RECOVERY_RATE_FLOOR_DPS;
            if !ok {
                last_bad = Some(ls.k);
            }
        },
    )?;
    let converged = match last_bad {
        None => Some(0.0),
        Some(k) if k + 1 >= n => None,
        Some(k) => Some((k + 1) as f64 / fs),
    };
    Ok(BootTimes {
        settled_s: settled.map(|k| k as f64 / fs),
        converged_s: converged,
    })
}

/// Cold boot, snapshot, warm boot of the same device (`duration_s` each). The snapshot
/// always comes from a cold boot with the dither (without it the estimate never
/// settles, and an unsettled snapshot is refused); `dither` says whether the boots that
/// are compared run with it.
pub fn warm_vs_cold(duration_s: f64, seed: u64, dither: bool) -> Result<WarmReport> {
    warm_vs_cold_gated(duration_s, seed, dither, None)
}

/// [`warm_vs_cold`] with the warm boot's start-up gate and settle window set to
/// `gates` = (gate s, window s) (`Estimator::set_start_gates`).
pub fn warm_vs_cold_gated(
    duration_s: f64,
    seed: u64,
    dither: bool,
    gates: Option<(f64, f64)>,
) -> Result<WarmReport> {
    let mut sc_d = Scenario::builtin("identify").context("the built-in 'identify' is missing")?;
    sc_d.duration_s = duration_s;
    let mut sc = sc_d.clone();
    if !dither {
        sc.estimator.dither_pump_hz = 0.0;
        sc.estimator.dither_scale_frac = 0.0;
    }
    let build = |sc: &Scenario| {
        core_config(sc)
            .build::<f32>()
            .map_err(|e| anyhow::anyhow!("core configuration: {e}"))
    };
    let mut source = build(&sc_d)?;
    let source_times = boot(&sc_d, seed, &mut source)?;
    let record = source.snapshot().encode();
    let cold = if dither {
        source_times
    } else {
        boot(&sc, seed, &mut build(&sc)?)?
    };
    let mut warm_est = build(&sc)?;
    match warm_est.boot_from(Some(&record)) {
        Start::Warm => {}
        Start::Cold(e) => anyhow::bail!("the cold boot's snapshot was refused: {e:?}"),
    }
    if let Some((g, w)) = gates {
        warm_est.set_start_gates(g, w);
    }
    anyhow::ensure!(Snapshot::decode(&record).is_ok());
    let warm = boot(&sc, seed.wrapping_add(1), &mut warm_est)?;
    Ok(WarmReport {
        duration_s,
        dither,
        cold,
        warm,
    })
}

/// A warm boot on a device that changed while it was off: the cold boot's snapshot of
/// `identify`, then a warm boot with the plant's ωy² scaled by `1 + wy2_rel` (the pump
/// dither on). Its timings (a warm start must not call the stale estimate settled early).
pub fn warm_after_change(duration_s: f64, seed: u64, wy2_rel: f64) -> Result<BootTimes> {
    let mut sc = Scenario::builtin("identify").context("the built-in 'identify' is missing")?;
    sc.duration_s = duration_s;
    let build = |sc: &Scenario| {
        core_config(sc)
            .build::<f32>()
            .map_err(|e| anyhow::anyhow!("core configuration: {e}"))
    };
    let mut source = build(&sc)?;
    boot(&sc, seed, &mut source)?;
    let record = source.snapshot().encode();
    let mut changed = sc.clone();
    changed.plant.wy2 *= 1.0 + wy2_rel;
    let mut warm_est = build(&changed)?;
    match warm_est.boot_from(Some(&record)) {
        Start::Warm => {}
        Start::Cold(e) => anyhow::bail!("the snapshot was refused: {e:?}"),
    }
    boot(&changed, seed.wrapping_add(1), &mut warm_est)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn warm_boot_converges_in_a_quarter_of_the_cold_time() {
        let r = warm_vs_cold(8.0, 13, true).unwrap();
        let (cold, warm) = (r.cold.converged_s.unwrap(), r.warm.converged_s.unwrap());
        assert!(cold > 0.5, "the cold boot converged at once: {r:?}");
        assert!(warm <= 0.25 * cold, "{r:?}");
        assert!(
            r.warm.settled_s.unwrap() < r.cold.settled_s.unwrap(),
            "{r:?}"
        );
        // the warm start's shorter start-up gate: settled one settle window after it
        let floor = paragyro_core::persist::WARM_GATE_S + 0.5;
        assert!(r.warm.settled_s.unwrap() <= floor + 1e-9, "{r:?}");
    }

    /// The warm first settle (the restored ω̂y² seeds the settle test, the window counts
    /// from the warm gate): on the same device it comes at the gate plus two fresh values;
    /// on a device whose ωy² moved by 0.5 % while off the fresh values disagree, and
    /// settled comes no earlier than a full window after the warm gate.
    #[test]
    fn warm_first_settle_is_early_only_on_the_same_device() {
        use paragyro_core::persist::WARM_GATE_S;
        let same = warm_vs_cold(4.0, 13, true).unwrap();
        let early = same.warm.settled_s.unwrap();
        assert!(early < WARM_GATE_S + 0.15, "{same:?}");
        assert!(early <= 0.25 * same.cold.settled_s.unwrap(), "{same:?}");
        let changed = warm_after_change(4.0, 13, 5e-3).unwrap();
        let late = changed.settled_s.unwrap_or(f64::INFINITY);
        println!("same device {early} s, changed device {late} s");
        assert!(late >= WARM_GATE_S + 0.5, "{changed:?} vs {same:?}");
    }

    #[test]
    fn without_dither_only_the_warm_boot_converges() {
        let r = warm_vs_cold(6.0, 13, false).unwrap();
        assert_eq!(r.cold.converged_s, None, "{r:?}");
        assert!(r.warm.converged_s.is_some(), "{r:?}");
    }

    #[test]
    #[ignore = "measurement: cargo test -p paragyro-simulator --lib warm_gates_swept -- --ignored --nocapture"]
    fn warm_gates_swept() {
        let pairs = [
            (0.5, 0.5),
            (0.25, 0.5),
            (0.1, 0.5),
            (0.02, 0.5),
            (0.25, 0.25),
            (0.25, 0.1),
            (0.1, 0.2),
            (0.05, 0.1),
        ];
        for dither in [true, false] {
            for seed in [13u64, 14, 15] {
                for (g, w) in pairs {
                    let r = warm_vs_cold_gated(20.0, seed, dither, Some((g, w))).unwrap();
                    println!(
                        "dither {dither} seed {seed} gate {g} window {w}: cold settled {:?} conv {:?}; warm settled {:?} conv {:?}; ratio {:?}",
                        r.cold.settled_s,
                        r.cold.converged_s,
                        r.warm.settled_s,
                        r.warm.converged_s,
                        r.settled_ratio()
                    );
                }
            }
        }
    }

    #[test]
    #[ignore = "measurement: cargo test -p paragyro-simulator --lib warm_start_measured -- --ignored --nocapture"]
    fn warm_start_measured() {
        for dither in [true, false] {
            let r = warm_vs_cold(20.0, 13, dither).unwrap();
            println!("{}", serde_json::to_string(&r).unwrap());
            println!(
                "settled ratio {:?}, converged ratio {:?}",
                r.settled_ratio(),
                r.converged_ratio()
            );
        }
    }
}
