//! Drives the core with the simulated gyro, scenario by scenario.
//!
//! Closed loop at 500 Hz: at sample k the lock-in outputs of the simulated plant, the
//! accelerations and the pump in effect go into `Estimator::step`, which returns the
//! pump command for sample k+1; the plant is then integrated over [t_k, t_{k+1}] with
//! the pump frequency sweeping linearly to that command (the DDS is phase-continuous).
//! The same loop runs the core in `f32` (what the chip runs) or `f64`.

use std::time::Instant;

use anyhow::Context;
use paragyro_core::physics::{Physical, physical_from_theta};
use paragyro_core::{Config, Estimator, Real, Sample, StepOutput};
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;
use std::collections::BTreeMap;

use crate::effects::Effects;
use crate::lockin::{LockinExt, LockinOut};
use crate::plant::{GyroSim, PlantInputs, SimConfig, Theta};
use crate::scenario::{EventKind, EventSpec, L0_M, PlantAt, PumpProfileSpec, Scenario};
use crate::summary::{
    Convergence, PhysicalValues, RateValidity, RunCounters, RunSummary, ThetaPair,
};
use crate::trace::{Event, RunResult, TraceRow};

pub use crate::trace::Precision;

/// Options of one run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Core precision.
    pub precision: Precision,
    /// Overrides the scenario's seed.
    pub seed: Option<u64>,
}

/// The core's configuration for a scenario: Table 2 defaults, the scenario's
/// front end, nominal design (with zero rate: the design knows no rotation) and
/// excitation.
pub fn core_config(sc: &Scenario) -> Config {
    let mut c = Config::table2();
    c.f0_hz = sc.sim.f0_hz;
    c.lockin_lpf_order = sc.sim.lockin_lpf_order;
    c.lockin_lpf_hz = sc.sim.lockin_lpf_hz;
    c.pump_profile = match sc.sim.pump_profile {
        PumpProfileSpec::Linear => paragyro_core::config::PumpProfile::Linear,
        PumpProfileSpec::Staircase => paragyro_core::config::PumpProfile::Staircase,
        // the two frequency steps follow the sweep, the scale holds: FOH and ZOH replicas
        PumpProfileSpec::HalfSteps => paragyro_core::config::PumpProfile::HalfSteps,
    };
    // rows are weighted to unit noise; a noise-free run keeps the 1 pm/√Hz weighting
    c.noise_pm_rthz = if sc.sim.noise_pm_rthz > 0.0 {
        sc.sim.noise_pm_rthz
    } else {
        1.0
    };
    if sc.sim.noise_pm_rthz <= 0.0 {
        // noise-free data can legitimately repeat values
        c.monitor.stuck_samples = 0;
    }
    let n = &sc.estimator.nominal;
    c.nominal = Physical {
        mu_x: n.mu_x,
        mu_y: n.mu_y,
        mu_xy: n.mu_xy,
        wx2: n.wx2,
        wy2: n.wy2,
        wxy2: n.wxy2,
        alpha_x: n.alpha_x,
        alpha_y: n.alpha_y,
        beta1: n.beta1,
        beta3: n.beta3,
        gamma: 0.0,
        gamma_p: 0.0,
        c_ax: 1.0,
        c_ay: 1.0,
    };
    c.pump_centre_hz = sc.pump_centre_hz();
    if let Some(w) = sc.estimator.rate_walk_dps {
        c.rate.walk_dps = w;
    }
    if let Some(t) = sc.estimator.retune_track_hz {
        c.retune.track_hz = t;
    }
    if let Some(m) = sc.estimator.rate_zero_memory_s {
        c.rate.zero_memory_s = m;
    }
    if let Some(kappa) = sc.estimator.drift_kappa {
        c.rls.drift_kappa = kappa;
    }
    c.dither.pump_hz = sc.estimator.dither_pump_hz;
    c.dither.freq_hz = sc.estimator.dither_freq_hz;
    c.dither.start_s = sc.estimator.dither_start_s;
    c.dither.scale_frac = sc.estimator.dither_scale_frac;
    c.dither.scale_freq_hz = sc.estimator.dither_scale_freq_hz;
    c.dither.enabled = sc.estimator.dither_pump_hz > 0.0;
    c.rls.forgetting = sc.estimator.forgetting;
    c.monitor.gate_startup_s = sc.estimator.gate_startup_s;
    c.retune.enabled = sc.estimator.retune;
    c.retune.ramp_s = sc.estimator.retune_ramp_s;
    c
}

/// Largest ω (pump half-frequency, non-dimensional) the run may reach, for the
/// integrator's step count (a simulated record names it in its header,
/// [`crate::record::SIM_OMEGA_MAX_KEY`]).
pub fn omega_max(sc: &Scenario, cfg: &Config) -> f64 {
    let f0 = sc.sim.f0_hz;
    let mut pump = sc.pump_centre_hz();
    for e in sc.control_events() {
        if let Some(c) = sc.pump_jump_centre_hz(&e) {
            pump = pump.max(c);
        }
    }
    // retune may move the centre up to the drive band's top: allow 3 % margin
    (pump + cfg.dither.pump_hz) / (2.0 * f0) * 1.03
}

/// Runs a scenario (and its twin, if it has one); `progress` gets the fraction done.
pub fn run(
    scenario: &Scenario,
    opts: &RunOptions,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<RunResult> {
    let wall = Instant::now();
    let twin_sc = scenario.twin_scenario();
    let share = if twin_sc.is_some() { 0.5 } else { 1.0 };
    let main = {
        let mut p = |f: f64| progress(f * share);
        match opts.precision {
            Precision::F32 => simulate::<f32>(scenario, opts, &mut p),
            Precision::F64 => simulate::<f64>(scenario, opts, &mut p),
        }
        .with_context(|| format!("scenario '{}'", scenario.name))?
    };
    let twin = match &twin_sc {
        Some(t) => {
            let mut p = |f: f64| progress(0.5 + 0.5 * f);
            let r = match opts.precision {
                Precision::F32 => simulate::<f32>(t, opts, &mut p),
                Precision::F64 => simulate::<f64>(t, opts, &mut p),
            }
            .with_context(|| format!("twin of scenario '{}'", scenario.name))?;
            Some(r)
        }
        None => None,
    };
    progress(1.0);
    let mut summary = summarize(scenario, opts, &main, twin.as_ref())?;
    summary.wall_seconds = wall.elapsed().as_secs_f64();
    Ok(RunResult {
        scenario: scenario.name.clone(),
        precision: opts.precision,
        trace: main.trace,
        events: main.events,
        summary,
        twin: twin.map(|t| t.trace),
    })
}

/// One simulated run's raw outcome.
pub struct SimRun {
    /// Per-sample trace.
    pub trace: Vec<TraceRow>,
    /// Events.
    pub events: Vec<Event>,
    /// Counters of the core at the end.
    pub counters: paragyro_core::Counters,
    /// Dither start, s.
    pub dither_start_s: f64,
    /// Final pump centre, Hz.
    pub pump_centre_final_hz: f64,
}

/// What the closed loop shows a visitor at each 500 Hz sample, after the core's step.
pub struct LoopSample<'a, T: Real> {
    /// Sample index.
    pub k: u64,
    /// Time, s.
    pub t_s: f64,
    /// The plant in force over [t_k, t_{k+1}] (truth).
    pub plant: &'a PlantAt,
    /// The lock-in outputs at t_k (f64, µm = L0).
    pub lockin: &'a LockinOut,
    /// What the core was given.
    pub sample: &'a Sample<T>,
    /// What the core returned.
    pub out: &'a StepOutput,
    /// The core after the step.
    pub est: &'a Estimator<T>,
    /// The linearisation point θ_nom the rows of this sample were formed about.
    pub nominal_before: &'a ([f64; 8], [f64; 6]),
}

/// The closed loop of the simulated gyro and the core, shared by every tool (runs,
/// calibration, records, benchmarks): at sample k the scenario's control events that
/// take effect by t_{k+1} go to the core, the lock-in outputs at t_k, the accelerations
/// and the pump in effect go into `step`, `visit` sees the result, and the plant is
/// integrated over [t_k, t_{k+1}] with the pump frequency and voltage scale sweeping
/// linearly to the core's command. `on_control` sees each control event (for logs).
pub fn closed_loop<T: Real>(
    sc: &Scenario,
    seed: u64,
    est: &mut Estimator<T>,
    on_control: impl FnMut(&EventSpec),
    visit: impl FnMut(&LoopSample<'_, T>),
) -> anyhow::Result<()> {
    closed_loop_with(sc, seed, &Device::default(), est, on_control, visit)
}

/// How the simulated device departs from the scenario's eq. (6): the effects of
/// [`crate::effects`] and the die temperature over the run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Device {
    /// The effects (all zero: the nominal model).
    pub effects: Effects,
    /// Die temperature: `None` (not recorded, and the thermal drift sees 25 °C), or
    /// `(start °C, rise K over the run)`, linear.
    pub temp: Option<(f64, f64)>,
}

impl Device {
    /// Die temperature at `t_s` of a run of `duration_s` (25 °C without a profile).
    pub fn temp_c(&self, t_s: f64, duration_s: f64) -> f64 {
        match self.temp {
            Some((t0, rise)) => t0 + rise * (t_s / duration_s.max(1e-9)).clamp(0.0, 1.0),
            None => crate::effects::T_REF_C,
        }
    }
}

/// [`closed_loop`] for a device with effects ([`Device`]): the plant and its measurement
/// get the effect terms, the lock-in its cut-off error, θ the thermal drift at the die
/// temperature of each sample.
pub fn closed_loop_with<T: Real>(
    sc: &Scenario,
    seed: u64,
    dev: &Device,
    est: &mut Estimator<T>,
    on_control: impl FnMut(&EventSpec),
    visit: impl FnMut(&LoopSample<'_, T>),
) -> anyhow::Result<()> {
    closed_loop_hooked(sc, seed, dev, est, &mut NoHooks, on_control, visit)
}

/// Where a fault campaign ([`crate::faults`]) may tamper with the closed loop. Every
/// method's default changes nothing (that is [`closed_loop_with`]).
pub trait LoopHooks<T: Real> {
    /// The plant in force over [t_k, t_{k+1}] (the truth: a parameter jump, a rate
    /// beyond full scale).
    fn plant(&mut self, _k: u64, _pa: &mut PlantAt) {}
    /// The core's step on the sample of tick `k` (a hook may change the sample, drop it
    /// by not stepping, or catch a panic); `last` is the previous tick's output.
    fn step(
        &mut self,
        _k: u64,
        est: &mut Estimator<T>,
        sample: &mut Sample<T>,
        _last: &StepOutput,
    ) -> StepOutput {
        est.step(sample)
    }
    /// The pump reaching the plant over [t_k, t_{k+1}], from `u0` to `u1` (a DDS write
    /// failure, a pump-amplitude collapse); `next` is what the next sample reports as in
    /// effect: the pump frequency, Hz, and the multiplier of the scenario's pump scale.
    fn inputs(
        &mut self,
        _k: u64,
        _u0: &mut PlantInputs,
        _u1: &mut PlantInputs,
        _next: &mut (f64, f64),
    ) {
    }
}

/// The hooks that change nothing.
struct NoHooks;
impl<T: Real> LoopHooks<T> for NoHooks {}

/// Gives the core one scenario control event; an event the core refuses (a pump centre
/// beyond its ±50 % or a dither beyond 5 % of the pump) is an error naming its time.
fn apply_control<T: Real>(
    sc: &Scenario,
    est: &mut Estimator<T>,
    e: &EventSpec,
) -> anyhow::Result<()> {
    match e.kind {
        EventKind::PumpJump { .. } => {
            if let Some(c) = sc.pump_jump_centre_hz(e) {
                anyhow::ensure!(
                    est.command_pump_centre(c, true),
                    "t = {} s: the core refused the pump jump to {c} Hz (more than ±50 % from \
                     its configured centre)",
                    e.t_s
                );
            }
        }
        EventKind::Dither { enabled, pump_hz } => {
            if let Some(a) = pump_hz {
                anyhow::ensure!(
                    est.set_dither_pump_hz(a),
                    "t = {} s: the core refused the dither of {a} Hz (not in [0, 5 % of the \
                     pump))",
                    e.t_s
                );
            }
            est.set_dither(enabled);
        }
        EventKind::Retune { enabled } => est.set_retune(enabled),
        _ => {}
    }
    Ok(())
}

/// [`closed_loop_with`] with [`LoopHooks`] between its stages (fault injection).
pub fn closed_loop_hooked<T: Real>(
    sc: &Scenario,
    seed: u64,
    dev: &Device,
    est: &mut Estimator<T>,
    hooks: &mut dyn LoopHooks<T>,
    mut on_control: impl FnMut(&EventSpec),
    mut visit: impl FnMut(&LoopSample<'_, T>),
) -> anyhow::Result<()> {
    let f0 = sc.sim.f0_hz;
    let w0 = sc.omega0_rad_s();
    let fs = est.config().fs_hz;
    let fx = dev.effects;
    // half steps: the simulator advances in half intervals, each with its own pump
    let substeps = sc.sim.pump_profile.sim_substeps();
    let simcfg = SimConfig {
        omega0_rad_s: w0,
        fs_hz: fs * substeps as f64,
        steps_per_period: sc.sim.steps_per_period,
        omega_max: omega_max(sc, est.config()),
        lpf_order: sc.sim.lockin_lpf_order,
        lpf_hz: sc.sim.lockin_lpf_hz * (1.0 + fx.lockin_mismatch),
        noise_density: sc.sim.noise_pm_rthz * 1e-6,
        seed,
    };
    let x0 = [sc.plant.initial_x_um, 0.0, sc.plant.initial_y_um, 0.0];
    let mut sim = GyroSim::new(&simcfg, x0).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
    // the vibration sits `beat` above the pump frequency the run starts at
    let vib_omega = std::f64::consts::TAU * (est.initial_pump_hz() + fx.vib_beat_hz) / w0;
    sim.set_effects(fx, vib_omega);
    let n = (sc.duration_s * fs).round() as u64;
    let accel_si = L0_M * w0 * w0;
    let controls = sc.control_events();
    let mid_theta = sc.has_rate_profile();
    let mut next_ctrl = 0usize;
    // the temperature sensor's noise: its own stream, so that the plant's is the same
    // with and without a sensor
    let mut temp_rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x7E3D_5E4C);
    let mut pump_hz = est.initial_pump_hz();
    // the core's multiplier on the pump voltage scale (the amplitude part of the dither)
    let mut scale_mult = 1.0;
    let mut last_out = StepOutput {
        pump_hz_next: pump_hz,
        pump_scale_next: 1.0,
        ..StepOutput::default()
    };
    for k in 0..=n {
        let t = k as f64 / fs;
        let t_next = (k + 1) as f64 / fs;
        while next_ctrl < controls.len() && controls[next_ctrl].t_s <= t_next + 1e-12 {
            let e = controls[next_ctrl];
            apply_control(sc, est, &e)?;
            on_control(&e);
            next_ctrl += 1;
        }
        let mut pa = sc.plant_at(t);
        hooks.plant(k, &mut pa);
        let s_k = sc.pump_scale_at(t) * scale_mult;
        let li = sim.lockin();
        let mut sample = Sample {
            lockin: li.to_precision::<T>(),
            accel_mps2: [
                T::from_f64(pa.accel_x * accel_si),
                T::from_f64(pa.accel_y * accel_si),
            ],
            pump_hz,
            pump_scale: T::from_f64(s_k),
            temp_c: sc
                .temperature
                .as_ref()
                .and_then(|tc| tc.read(t, temp_rng.sample(StandardNormal)))
                .map(T::from_f64),
        };
        let nominal_before = est.nominal_theta();
        let out = hooks.step(k, est, &mut sample, &last_out);
        last_out = out;
        visit(&LoopSample {
            k,
            t_s: t,
            plant: &pa,
            lockin: &li,
            sample: &sample,
            out: &out,
            est,
            nominal_before: &nominal_before,
        });
        if k == n {
            break;
        }
        let pa1 = sc.plant_at(t_next);
        // θ held over the interval: at its start, or (a sine or chirp of the rate) at
        // its midpoint
        let held = if mid_theta {
            sc.plant_at(0.5 * (t + t_next))
        } else {
            pa
        };
        let mut theta = Theta {
            drive: held.theta_drive,
            sense: held.theta_sense,
        };
        if fx.tcf_ppm_k != 0.0 {
            // the die temperature over the interval, at its midpoint
            let tc = dev.temp_c(0.5 * (t + t_next), sc.duration_s);
            fx.thermal_theta(
                &mut theta.drive,
                &mut theta.sense,
                pa.phys[3],
                pa.phys[4],
                tc,
            );
        }
        let u1 = PlantInputs {
            omega: out.pump_hz_next / (2.0 * f0),
            s: sc.pump_scale_at(t_next) * out.pump_scale_next,
            ax: pa1.accel_x,
            ay: pa1.accel_y,
        };
        // the pump sweeps linearly to the command, or (staircase) the command holds
        // over the whole interval, or (half steps) two steps around the sweep
        let u0 = match sc.sim.pump_profile {
            PumpProfileSpec::Linear | PumpProfileSpec::HalfSteps => PlantInputs {
                omega: pump_hz / (2.0 * f0),
                s: s_k,
                ax: pa.accel_x,
                ay: pa.accel_y,
            },
            PumpProfileSpec::Staircase => PlantInputs {
                ax: pa.accel_x,
                ay: pa.accel_y,
                ..u1
            },
        };
        let (mut u0, mut u1) = (u0, u1);
        let mut next = (out.pump_hz_next, out.pump_scale_next);
        hooks.inputs(k, &mut u0, &mut u1, &mut next);
        if sc.sim.pump_profile == PumpProfileSpec::HalfSteps {
            // the frequency 1/4 and 3/4 of the way to the command, the scale one step
            let om = |f: f64| u0.omega + (u1.omega - u0.omega) * f;
            let (first, second) = ((om(0.25), u1.s), (om(0.75), u1.s));
            advance_in_halves(&mut sim, &theta, &u0, &u1, first, second);
        } else {
            sim.advance(&theta, &u0, &u1);
        }
        (pump_hz, scale_mult) = next;
    }
    Ok(())
}

/// One sample interval of a simulator built at twice the sample rate: the pump (ω, s)
/// held at `first` over the first half and at `second` over the second, the
/// accelerations moving linearly from `u0`'s to `u1`'s as in [`GyroSim::advance`] (the
/// pump of `u0` and `u1` is not used). [`PumpProfileSpec::HalfSteps`] here, the DDS's two
/// words in the firmware-in-the-loop plant.
pub fn advance_in_halves(
    sim: &mut GyroSim,
    theta: &Theta,
    u0: &PlantInputs,
    u1: &PlantInputs,
    first: (f64, f64),
    second: (f64, f64),
) {
    let (axm, aym) = (0.5 * (u0.ax + u1.ax), 0.5 * (u0.ay + u1.ay));
    let held = |(omega, s): (f64, f64), ax: f64, ay: f64| PlantInputs { omega, s, ax, ay };
    sim.advance(theta, &held(first, u0.ax, u0.ay), &held(first, axm, aym));
    sim.advance(theta, &held(second, axm, aym), &held(second, u1.ax, u1.ay));
}

/// Runs one scenario (no twin) with the core in precision `T`.
pub fn simulate<T: Real>(
    sc: &Scenario,
    opts: &RunOptions,
    progress: &mut dyn FnMut(f64),
) -> anyhow::Result<SimRun> {
    let cfg = core_config(sc);
    let mut est: Estimator<T> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let w0 = sc.omega0_rad_s();
    let n = (sc.duration_s * cfg.fs_hz).round() as u64;
    let mut events: Vec<Event> = sc
        .events
        .iter()
        .filter(|e| !e.kind.is_control())
        .map(|e| Event {
            t_s: e.t_s,
            what: describe(&e.kind),
        })
        .collect();
    let mut control_log: Vec<Event> = Vec::new();
    let mut trace = Vec::with_capacity(n as usize + 1);
    let mut last_progress = Instant::now();
    closed_loop(
        sc,
        opts.seed.unwrap_or(sc.seed),
        &mut est,
        |e| {
            control_log.push(Event {
                t_s: e.t_s,
                what: describe(&e.kind),
            })
        },
        |ls| {
            let (th1, th2) = ls.est.theta();
            let phys = physical_from_theta(&th1, &th2).as_array();
            let counters = ls.est.counters();
            trace.push(TraceRow {
                t_s: ls.t_s,
                pump_hz: ls.sample.pump_hz,
                pump_centre_hz: ls.est.pump_centre_hz(),
                pump_scale: ls.sample.pump_scale.to_f64(),
                theta_drive_true: ls.plant.theta_drive,
                theta_sense_true: ls.plant.theta_sense,
                theta_drive_est: th1,
                theta_sense_est: th2,
                phys_true: ls.plant.phys,
                phys_est: phys,
                rate_dps_true: ls.plant.rate_dps,
                rate_dps_est: ls.out.rate.rate_dps,
                drive_amp_um: ls.lockin.x_abs(1),
                sense_amp_um: ls.lockin.y_abs(1),
                health: ls.out.health.bits(),
                resets: counters.resets_drive + counters.resets_sense,
                bad_samples: counters.bad_samples,
                rate_dps_slow: paragyro_core::physics::rate_dps_from_gamma(phys[10], w0),
                quadrature_dps: ls.out.rate.quadrature_dps,
                rate_valid: ls.out.rate.valid,
                temp_c: sc.temp_c(ls.t_s).unwrap_or(f64::NAN),
                drift_ppm_s: ls.est.drift_ppm_s(),
                tcf_ppm_k: ls.est.thermal().tcf_ppm_k,
                drift_alarms: counters.drift_alarms,
            });
            for (bit, what) in EVENT_NAMES {
                if ls.out.events & bit != 0 {
                    events.push(Event {
                        t_s: ls.t_s,
                        what: what.to_string(),
                    });
                }
            }
            if ls.k % 50 == 0 && last_progress.elapsed().as_millis() >= 100 {
                progress(ls.k as f64 / n as f64);
                last_progress = Instant::now();
            }
        },
    )?;
    events.extend(control_log);
    events.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    Ok(SimRun {
        trace,
        events,
        counters: est.counters(),
        dither_start_s: cfg.dither.start_s,
        pump_centre_final_hz: est.pump_centre_hz(),
    })
}

const EVENT_NAMES: [(u8, &str); 7] = [
    (
        paragyro_core::estimator::event::CHANGE_DRIVE,
        "change detected (drive): covariance reset",
    ),
    (
        paragyro_core::estimator::event::CHANGE_SENSE,
        "change detected (sense): covariance reset",
    ),
    (
        paragyro_core::estimator::event::RETUNE_START,
        "retune started",
    ),
    (paragyro_core::estimator::event::RETUNE_DONE, "retune done"),
    (
        paragyro_core::estimator::event::RETUNE_ABORT,
        "retune aborted: drive lock lost",
    ),
    (
        paragyro_core::estimator::event::BAD_INPUT,
        "bad input sample skipped",
    ),
    (paragyro_core::estimator::event::SETTLED, "estimate settled"),
];

fn describe(k: &EventKind) -> String {
    match k {
        EventKind::Ramp {
            param,
            to,
            duration_s,
        } => format!("ramp {} → {to} over {duration_s} s", param.name()),
        EventKind::ScaleTheta { factor } => format!("θ scaled ×{factor}"),
        EventKind::PumpJump {
            centre_hz,
            to_sense_resonance,
        } => match centre_hz {
            Some(c) => format!("pump jump to {c:.1} Hz"),
            None if *to_sense_resonance => "pump jump to the sense resonance".into(),
            None => "pump jump".into(),
        },
        EventKind::Dither { .. } => k.to_string(),
        EventKind::Retune { enabled } => {
            format!("retune {}", if *enabled { "allowed" } else { "forbidden" })
        }
        EventKind::PumpScale { s, ramp_s } => format!("pump scale → {s} over {ramp_s} s"),
        EventKind::RateSine { .. } | EventKind::RateChirp { .. } => k.to_string(),
    }
}

fn rel(est: f64, tru: f64) -> f64 {
    if tru != 0.0 {
        (est - tru).abs() / tru.abs()
    } else {
        (est - tru).abs()
    }
}

/// Time (s, from `t0`) after which |est − true|/|true| of θ component `j` stays below
/// `tol` until the end of `rows` (None if it never does).
pub fn settle_time(rows: &[TraceRow], j: usize, tol: f64, t0: f64) -> Option<f64> {
    let get = |r: &TraceRow| {
        if j < 8 {
            rel(r.theta_drive_est[j], r.theta_drive_true[j])
        } else {
            rel(r.theta_sense_est[j - 8], r.theta_sense_true[j - 8])
        }
    };
    let rows: Vec<&TraceRow> = rows.iter().filter(|r| r.t_s >= t0).collect();
    // NaN counts as outside the tolerance
    let last_bad = rows.iter().rposition(|r| get(r).is_nan() || get(r) >= tol);
    match last_bad {
        None => Some(0.0),
        Some(i) if i + 1 == rows.len() => None,
        Some(i) => Some(rows[i + 1].t_s - t0),
    }
}

/// The summary of a run (its `wall_seconds` left at 0 for the caller).
fn summarize(
    sc: &Scenario,
    opts: &RunOptions,
    main: &SimRun,
    twin: Option<&SimRun>,
) -> anyhow::Result<RunSummary> {
    let last = main
        .trace
        .last()
        .ok_or_else(|| anyhow::anyhow!("scenario '{}': the run has no sample", sc.name))?;
    let theta_true = ThetaPair {
        drive: last.theta_drive_true,
        sense: last.theta_sense_true,
    };
    let theta_est = ThetaPair {
        drive: last.theta_drive_est,
        sense: last.theta_sense_est,
    };
    // convergence after the dither starts
    let t0 = main.dither_start_s;
    let settle = |tol: f64| ThetaPair::from_fn(|j| settle_time(&main.trace, j, tol, t0));
    let measures: BTreeMap<String, Option<f64>> = sc
        .measure_values(&main.trace, twin.map(|t| t.trace.as_slice()))
        .into_iter()
        .collect();
    let m = |k: &str| measures.get(k).copied().flatten();
    let ratio = |num: &str, den: &str| Some(m(num)? / m(den)?);
    Ok(RunSummary {
        scenario: sc.name.clone(),
        precision: opts.precision,
        seed: opts.seed.unwrap_or(sc.seed),
        sim_seconds: last.t_s,
        theta_rel_err: ThetaPair::from_fn(|j| {
            rel(
                theta_est.get(j).unwrap_or(f64::NAN),
                theta_true.get(j).unwrap_or(f64::NAN),
            )
        }),
        theta_true,
        theta_est,
        physical_true: PhysicalValues::from_array(last.phys_true),
        physical_est: PhysicalValues::from_array(last.phys_est),
        rate_dps_true: last.rate_dps_true,
        rate_dps_est: last.rate_dps_est,
        rate_rel_err: rel(last.rate_dps_est, last.rate_dps_true),
        rate_validity: RateValidity::of_trace(&main.trace),
        wy2_true_final: last.phys_true[4],
        wy2_est_final: last.phys_est[4],
        pump_centre_final_hz: main.pump_centre_final_hz,
        convergence_after_dither_start: Convergence {
            within_10pct_s: settle(0.1),
            within_1pct_s: settle(0.01),
        },
        counters: RunCounters::from(&main.counters),
        sense_amp_ratio: ratio("sense_amp_detuned", "sense_amp_tuned"),
        sense_amp_after_drift_ratio: ratio("sense_amp_after_drift", "sense_amp_before_drift"),
        sense_amp_after_retune_ratio: ratio("sense_amp_after_retune", "sense_amp_before_drift"),
        twin_pump_centre_final_hz: twin.map(|t| t.pump_centre_final_hz),
        measures,
        wall_seconds: 0.0,
    })
}

/// Residual standard deviation of each regression row with the TRUE θ, per 1 pm/√Hz of
/// front-end noise: the row weights (`Config::row_sigma_*`) for a device like the
/// scenario's. Runs the scenario with the `f64` core and evaluates
/// `y − Φ·(θ_true − θ_nom)` on every sample from `from_s` on.
pub fn calibrate_rows(sc: &Scenario, from_s: f64) -> anyhow::Result<([f64; 5], [f64; 5])> {
    let cfg = core_config(sc);
    let mut est: Estimator<f64> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let (mut s1, mut s2) = ([0.0f64; 5], [0.0f64; 5]);
    let mut count = 0usize;
    closed_loop(
        sc,
        sc.seed,
        &mut est,
        |_| {},
        |ls| {
            if ls.t_s < from_s {
                return;
            }
            let (n1, n2) = ls.nominal_before;
            let rows = ls.est.last_rows();
            for r in 0..5 {
                let mut e1 = rows.drive_y[r];
                for j in 0..8 {
                    e1 -= rows.drive_phi[r][j] * (ls.plant.theta_drive[j] - n1[j]);
                }
                let mut e2 = rows.sense_y[r];
                for j in 0..6 {
                    e2 -= rows.sense_phi[r][j] * (ls.plant.theta_sense[j] - n2[j]);
                }
                s1[r] += e1 * e1;
                s2[r] += e2 * e2;
            }
            count += 1;
        },
    )?;
    anyhow::ensure!(count > 10, "calibration window too short");
    let noise = if sc.sim.noise_pm_rthz > 0.0 {
        sc.sim.noise_pm_rthz
    } else {
        1.0
    };
    let f = |s: [f64; 5]| s.map(|v| (v / count as f64).sqrt() / noise);
    Ok((f(s1), f(s2)))
}
