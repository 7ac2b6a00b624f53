//! Firmware in the loop (firmware/README.md, "Firmware in the loop"): QEMU runs the `fil`
//! board (the real drivers, `App::tick` and the board loop), `paragyro-fil` plays the
//! chips every tick from the full-rate plant, and each scenario's verdict is checked
//! against the host-only closed loop of the same scenario (f32 core, same configuration).
//!
//! The `fil` image is built once (its own target directory, `target/fil/build`) and the
//! instruction-count plugin compiled with `cc`; each scenario writes its
//! `target/fil/test/<name>/summary.json`. Set `PARAGYRO_SKIP_QEMU=1` to skip (a machine
//! without qemu-system-arm; `cargo xtask test` installs it).

use std::path::PathBuf;
use std::sync::OnceLock;

use paragyro_fil::{BoardPump, LoopScenario, Summary, budget, build, default_out};

fn skip() -> bool {
    let s = std::env::var("PARAGYRO_SKIP_QEMU").as_deref() == Ok("1");
    if s {
        eprintln!("PARAGYRO_SKIP_QEMU=1: the firmware-in-the-loop test is skipped");
    }
    s
}

/// The `fil` image and the plugin, built once per test binary.
fn artefacts() -> &'static (PathBuf, PathBuf) {
    static A: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    A.get_or_init(|| {
        let out = default_out();
        let elf = build::firmware(&out.join("build"), &out).expect("building the fil firmware");
        let plugin = build::plugin(&out).expect("building the QEMU plugin");
        (elf, plugin)
    })
}

fn run(ls: &LoopScenario, pump: BoardPump) -> Summary {
    let (elf, plugin) = artefacts();
    let tag = match pump {
        BoardPump::HalfSteps => ls.name.clone(),
        other => format!("{}-{}", ls.name, other.name()),
    };
    let out = default_out().join("test").join(tag);
    paragyro_fil::run(ls, elf, plugin, &out, None, pump).expect("the loop session")
}

fn assert_pass(s: &Summary) {
    assert!(s.pass, "{}: {:?}", s.scenario, s.failures);
    assert_eq!(s.exit_code, Some(0));
    assert_eq!(s.dds_unlocked_ticks, 0);
    assert!(s.io_update_pulses > 0 && s.dds_writes > 0);
    // every passing scenario within the tick budget (mean 12 000, max 15 000, exact)
    let over = budget::tick_guard(s.instr_mean, s.instr_max);
    assert!(over.is_empty(), "{}: {over:?}", s.scenario);
}

#[test]
fn drift_retune_converges_and_retunes_in_the_loop() {
    if skip() {
        return;
    }
    let s = run(&paragyro_fil::drift_retune().unwrap(), BoardPump::HalfSteps);
    assert_pass(&s);
    assert!(s.converged && s.retunes >= 1, "{s:?}");
    assert!(
        s.sense_amp_ratio >= 1.0,
        "sense amplitude ratio {}",
        s.sense_amp_ratio
    );
    assert_eq!((s.ticks, s.bad_ticks), (5001, 0));
    // two DDS steps per sample: both pulses in the log, the rate's mean over the last
    // second within 0.1 % on this seed (measured −0.045 %; over seeds 1–10 −0.112 to
    // −0.016 %, mean −0.064 %, over 0.1 % on seed 3; the host-only loop's −0.035 to
    // +0.077 %, mean +0.018 %: `cargo run --release -p paragyro-fil -- drift-retune --seed
    // N`, `summary.json`; firmware/docs/notes.md "DDS words")
    assert!(
        s.half_period_pulses > 1000,
        "{} half-period pulses",
        s.half_period_pulses
    );
    assert!(
        (s.rate_dps_mean_last_s / s.rate_dps_true - 1.0).abs() <= 1e-3,
        "rate {} for {}",
        s.rate_dps_mean_last_s,
        s.rate_dps_true
    );
    // the host-only loop of the same scenario agrees (tolerance: 10 % of the drift)
    assert!(s.host_only.converged && s.host_only.retunes == s.retunes);
    assert!(s.wy2_fil_vs_host <= s.wy2_fil_vs_host_tol);
    // the retune took the DDS to the new sense resonance 2·√1.03·f0
    let f0 = paragyro_core::physics::F0_TABLE2_HZ;
    let resonance = 2.0 * 1.03f64.sqrt() * f0;
    assert!(
        (s.pump_end_hz - resonance).abs() < 3.73,
        "pump {} vs {resonance}",
        s.pump_end_hz
    );
    // exact counts, one per tick, within the tick budget (mean 12 000, max 15 000)
    assert!(s.instr_mean > 5_000.0 && s.instr_max as f64 >= s.instr_mean);
    let over = budget::tick_guard(s.instr_mean, s.instr_max);
    assert!(over.is_empty(), "{over:?}");
    // the re-linearisation is spread over ticks (core/src/estimator/relin.rs): the
    // costliest tick is within 3 300 of the mean (`cargo fw-loop`, `summary.json`
    // `instr_max` − `instr_mean`)
    assert!(
        s.instr_max as f64 - s.instr_mean <= 3_300.0,
        "max {} vs mean {}",
        s.instr_max,
        s.instr_mean
    );
    assert!(
        s.stack_peak_bytes > 4_096,
        "stack peak {}",
        s.stack_peak_bytes
    );
}

#[test]
fn startup_identification_in_the_loop() {
    if skip() {
        return;
    }
    let s = run(&paragyro_fil::startup().unwrap(), BoardPump::HalfSteps);
    assert_pass(&s);
    assert_eq!((s.ticks, s.bad_ticks, s.retunes), (2001, 0, 0));
    assert!((s.wy2_est - 1.0265).abs() <= 5e-4, "ω̂y² {}", s.wy2_est);
    assert!(
        (s.rate_dps_est - 150.0).abs() <= 3.0,
        "rate {}",
        s.rate_dps_est
    );
}

#[test]
fn the_scale_factor_and_nonlinearity_over_300_dps_hold_in_the_loop() {
    if skip() {
        return;
    }
    let s = run(&paragyro_fil::rate_ramp().unwrap(), BoardPump::HalfSteps);
    // the verdict holds both to issue 10's 0.1 % (1 000 ppm)
    assert_pass(&s);
    let (fw, host) = (s.ramp.unwrap(), s.host_only.ramp.unwrap());
    assert_eq!(fw.bins, 30, "{fw:?}");
    // measured on seeds 1–10: the scale factor −20.6 to +17.6 ppm (host-only −18.9 to
    // +17.3), the nonlinearity 41–80 ppm FS (47–83); the same fit of the same leg, so the loop's
    // ADC, accelerometer and DDS words move them by a few ppm, not hundreds
    assert!(
        fw.scale_factor_err_ppm.abs() <= 100.0,
        "scale factor {} ppm",
        fw.scale_factor_err_ppm
    );
    assert!(
        (fw.scale_factor_err_ppm - host.scale_factor_err_ppm).abs() <= 30.0,
        "scale factor {} ppm against the host-only loop's {}",
        fw.scale_factor_err_ppm,
        host.scale_factor_err_ppm
    );
    assert!(
        fw.nonlinearity_ppm_fs <= 200.0,
        "nonlinearity {} ppm FS",
        fw.nonlinearity_ppm_fs
    );
}

#[test]
fn rate_step_in_the_loop() {
    if skip() {
        return;
    }
    let s = run(&paragyro_fil::rate_step().unwrap(), BoardPump::HalfSteps);
    assert_pass(&s);
    assert_eq!(s.rate_dps_true, 100.0);
    assert!(
        (s.rate_dps_est - 100.0).abs() <= 2.0,
        "rate {}",
        s.rate_dps_est
    );
    assert!((s.rate_dps_est - s.host_only.rate_dps_est).abs() <= 1.0);
    // the two DDS steps told to the core exactly (`Estimator::set_pump_sweep_hz`): the
    // slow RLS takes the step as the host-only loop's does, its gate ended by the end and
    // the rate at the last tick with the host-only loop's (`cargo run --release -p
    // paragyro-fil -- rate-step --seed N`, `summary.json`)
    assert_eq!(
        s.health_end & (1 << 6),
        0,
        "gated at the end: {:#b}",
        s.health_end
    );
    assert!(
        (s.rate_dps_est - s.host_only.rate_dps_est).abs() <= 0.25,
        "rate at the end {} against the host-only loop's {}",
        s.rate_dps_est,
        s.host_only.rate_dps_est
    );
    // the scale factor over the last second (measured +0.043 %; firmware/docs/notes.md
    // "Firmware in the loop")
    assert!(
        (s.rate_dps_mean_last_s - 100.0).abs() <= 0.3,
        "rate {}",
        s.rate_dps_mean_last_s
    );
}

#[test]
fn spi_faults_are_flagged_counted_and_survived() {
    if skip() {
        return;
    }
    let ls = paragyro_fil::spi_faults().unwrap();
    let s = run(&ls, BoardPump::HalfSteps);
    assert_pass(&s);
    let c = &s.fw_counters;
    // five CRC errors, one missing DRDY (both frames not ready), ten failed DDS ticks,
    // the accelerometer stuck for 50 ticks: refused from the 8th identical read (43)
    assert_eq!(c.adc_crc_errors, 5);
    assert_eq!((c.drdy_missing, c.adc_not_ready), (1, 2));
    assert_eq!((c.dds_errors, s.dds_fault_ticks), (10, 10));
    assert_eq!(s.adc_fault_ticks, 6);
    assert_eq!((c.accel_stuck, c.accel_errors), (43, 0));
    assert_eq!(
        s.bad_ticks,
        5 + 1 + 43,
        "exactly the CRC, DRDY and stuck ticks are flagged"
    );
    assert_eq!(c.core_bad_samples, 49);
    assert_eq!((c.adc_spi_errors, c.guard_clamps), (0, 0));
    // survived: converged and retuned as without faults
    assert!(s.converged && s.retunes >= 1 && s.sense_amp_ratio >= 1.0);
}

/// The pump the estimator can trust, decided in the loop: a DDS that steps once per
/// sample (at IO_UPDATE) with a core told `Linear` fails. Before the rate walk it never
/// retuned (sense amplitude ratio < 0.8); with it, it retunes (ω̂y² 3.4e-4 off, the
/// staircase core's 3e-7) but its rate reads −505 °/s for a true 150, and the loop and
/// its host-only run disagree. (The boards step twice per sample: the tests above.)
#[test]
fn a_linear_replica_on_the_stepping_dds_fails() {
    if skip() {
        return;
    }
    let s = run(
        &paragyro_fil::drift_retune().unwrap(),
        BoardPump::StaircaseLinear,
    );
    assert!(!s.pass);
    assert!(
        (s.rate_dps_est - s.rate_dps_true).abs() > 0.1 * s.rate_dps_true.abs(),
        "rate {} °/s for {}",
        s.rate_dps_est,
        s.rate_dps_true
    );
}

/// The drive falls out of its band (ωx² 1 → 1.1): the drive dies, the core flags it
/// (`drive_locked` cleared, as in the host-only loop) and does not retune on it; every
/// sample stays valid and the pump inside the guard.
#[test]
fn the_drive_falling_out_of_its_band_is_flagged() {
    if skip() {
        return;
    }
    let s = run(&paragyro_fil::out_of_band().unwrap(), BoardPump::HalfSteps);
    assert_pass(&s);
    assert!(
        s.drive_amp_ratio < 0.01,
        "drive ratio {}",
        s.drive_amp_ratio
    );
    assert_eq!(
        s.host_only.health_end & paragyro_fil::verdict::DRIVE_LOCKED_BIT,
        0
    );
    assert_eq!(
        (s.retunes, s.bad_ticks, s.fw_counters.guard_clamps),
        (0, 0, 0)
    );
}

/// The firmware path's rate error beyond the host-only loop's, while the dither runs
/// (0.102–0.104 °/s rms on `rate-step` seeds 1–10 with the AD9959 at 125 MHz and the wide
/// filter's band taps; firmware/docs/notes.md "DDS words"), is the DDS's words: with the
/// host-only loop's pump rounded to them as the board's are (the 10-bit amplitude, the
/// frequency's two whole-word steps with error feedback and their sweep told to the core),
/// the two loops' rates agree sample by sample within 0.05 °/s rms (measured 0.002–0.004
/// on seeds 1–10) and their means within 0.05 °/s on this seed (−0.039; on seeds 1–10
/// −0.061 to +0.026, beyond 0.05 on seed 4): `cargo run --release -p paragyro-fil --
/// rate-step --seed N --host-amplitude-words --host-frequency-words`.
#[test]
fn the_dds_words_are_what_the_firmware_path_adds_to_the_rate() {
    if skip() {
        return;
    }
    let mut ls = paragyro_fil::rate_step().unwrap();
    ls.name = "rate-step-board-words".into();
    ls.host_words = paragyro_fil::verdict::HostWords {
        amplitude: true,
        frequency: true,
    };
    let s = run(&ls, BoardPump::HalfSteps);
    assert_pass(&s);
    let (e, h) = (
        s.rate_error.expect("a constant rate at the end"),
        s.host_only.rate_error.expect("a constant rate at the end"),
    );
    let apart = e.vs_host_only_rms_dps.expect("the same ticks");
    assert!(apart < 0.05, "{e:?} against {h:?}");
    assert!(
        (e.mean_dps - h.mean_dps).abs() < 0.05,
        "{e:?} against {h:?}"
    );
}

/// A 10 K warm-up over 20 s (host-sim/scenarios/warm-up.toml at 4 g): the firmware takes the
/// die temperature from the accelerometer's burst (the chip model adds the scenario's
/// sensor noise) and the core follows the drift as issue 30 asks, in the loop and in the
/// host-only loop (the verdict, `paragyro_fil::WarmUp`): no covariance reset after the
/// start-up, the rate flagged valid on ≥ 99 % of the ramp, its error's rms during the ramp
/// ≤ 1.2× its rms before it, the sense amplitude ≥ 98 % of the oracle twin's in every
/// second; here also the pump centre within 0.5 Hz of twice the sense resonance through the
/// ramp and at the end (the tracking's dead band is 0.25 Hz). Measured (`cargo run
/// --release -p paragyro-fil -- warm-up`, seed 1, `summary.json` `warm_up`): 0 resets, the
/// rate valid on 99.2 % of the ramp, its error 1.06× (the host-only loop 1.18×), the sense
/// amplitude 100.2 % of the oracle's, the pump within 0.23 Hz. Its ticks are within the
/// budget (the next test).
#[test]
fn a_warm_up_is_followed_without_resets_in_the_loop() {
    if skip() {
        return;
    }
    let s = run(&paragyro_fil::warm_up().unwrap(), BoardPump::HalfSteps);
    assert!(s.pass, "{}: {:?}", s.scenario, s.failures);
    assert_eq!(s.exit_code, Some(0));
    assert_eq!(s.dds_unlocked_ticks, 0);
    let w = s.warm_up.as_ref().expect("the warm-up's figures");
    assert_warm_up_targets(w);
    assert_warm_up_targets(s.host_only.warm_up.as_ref().expect("host-only figures"));
    assert!(w.pump_offset_end_hz.abs() <= 0.5, "{w:?}");
    assert!(w.pump_offset_max_ramp_hz <= 0.5, "{w:?}");
    // the pump had twice the sense resonance's 7.2 Hz fall to follow
    assert!(w.pump_target_move_hz < -7.0, "{w:?}");
    assert_eq!((s.ticks, s.bad_ticks), (13501, 0));
    assert!(s.instr_max <= 15_000, "largest tick {}", s.instr_max);
}

/// Issue 30's targets on a warm-up's figures: no covariance reset after the start-up, the
/// rate valid on ≥ 99 % of the ramp (and the loop's health allowing it), its error ≤ 1.2×
/// its rms before the ramp, the sense amplitude ≥ 98 % of the oracle twin's every second.
fn assert_warm_up_targets(w: &paragyro_fil::verdict::WarmUpNumbers) {
    assert_eq!((w.resets_drive_after, w.resets_sense_after), (0, 0));
    assert!(w.rate_health_share >= 0.99, "{w:?}");
    assert!(w.rate_valid_share.is_some_and(|v| v >= 0.99), "{w:?}");
    assert!(w.rate_err_ratio <= 1.2, "{w:?}");
    assert!(
        w.sense_amp_vs_oracle_min.is_some_and(|a| a >= 0.98),
        "{w:?}"
    );
}

/// The warm-up over 40 s at equal TCFs (both −30 ppm/K; `paragyro-fil warm-up --ramp-s 40
/// --tcf-ppm-k -30,-30`) meets issue 30's targets in the loop and the host-only loop,
/// within the tick budget (mean 12 000, max 15 000 instructions, exact). Measured (seed 1,
/// `summary.json`): 0 resets, the rate valid on 99.9 % of the ramp, its error 1.03× its rms
/// before the ramp (the host-only loop 1.17×), the sense amplitude 100.2 % of the oracle's;
/// ticks mean 11 811, max 14 262. The dither runs throughout, so every tick updates both
/// RLS and writes both pump steps to the DDS, one SPI frame each
/// (`firmware/scripts/fil-profile.sh warm-up`); `fw-drift-retune`, whose mean the README's
/// budget row quotes, stops its dither for its last 4 of 10 s.
#[test]
fn a_40_s_warm_up_at_equal_tcfs_holds_in_the_loop_within_the_tick_budget() {
    if skip() {
        return;
    }
    let shape = paragyro_fil::WarmUpShape {
        ramp_s: Some(40.0),
        rise_k: None,
        tcf_ppm_k: Some(vec![-30.0, -30.0]),
    };
    let s = run(
        &paragyro_fil::warm_up_shaped(&shape).unwrap(),
        BoardPump::HalfSteps,
    );
    assert_pass(&s);
    assert_warm_up_targets(s.warm_up.as_ref().expect("the warm-up's figures"));
    assert_warm_up_targets(s.host_only.warm_up.as_ref().expect("host-only figures"));
    assert_eq!((s.ticks, s.bad_ticks), (23_501, 0));
}
