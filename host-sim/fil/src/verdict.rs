//! The verdict of a session (`target/fil/summary.json`) and the host-only closed loop of
//! the same scenario it is compared with.

use paragyro_core::Estimator;
use paragyro_firmware::drivers::ad9959::{AmplitudeWord, DEFAULT_SYSCLK_HZ, FTW_SCALE};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::rate_response::{RampFit, ramp_fit};
use paragyro_simulator::runner;
use paragyro_simulator::scenario::{EventKind, PlantParam, Scenario};
use serde::{Deserialize, Serialize};

use crate::chips::Faults;
use crate::session::{BoardPump, Session};
use crate::{LoopScenario, RampLeg, WarmUp};

mod warm_up;
use warm_up::warm_up_checks;
pub use warm_up::{PUMP_MEAN_S, RATE_HEALTH_BITS, RETUNING_BIT, WarmUpNumbers, WarmUpTick};

/// |ω̂y² − ωy²| at the end must be at most this fraction of the drift |ωy²(end) − ωy²(start)|
/// (the replay's rule, `paragyro_firmware::run::WY2_TOL_OF_DRIFT`).
pub const WY2_TOL_OF_DRIFT: f64 = paragyro_firmware::run::WY2_TOL_OF_DRIFT;
/// Without a drift: |ω̂y² − ωy²| ≤ this, absolute.
pub const WY2_TOL_NO_DRIFT: f64 = 5e-4;
/// The loop against the host-only closed loop: |ω̂y²(FIL) − ω̂y²(host)| at the end at most
/// this fraction of the drift (or [`WY2_TOL_NO_DRIFT`]).
pub const WY2_FIL_VS_HOST_OF_DRIFT: f64 = 0.1;
/// The rate estimate at the end within this fraction of the true rate (where the scenario
/// checks the rate; the staircase pump with the ZOH replica biases the rate by +1.2 % on
/// `identify`, firmware/docs/notes.md "Pump profile").
pub const RATE_TOL_FRAC: f64 = 0.02;
/// The loop against the host-only loop: |rate(FIL) − rate(host)| at the end at most this
/// fraction of the true rate.
pub const RATE_FIL_VS_HOST_FRAC: f64 = 0.01;
/// The ramp's scale-factor error at most this, ppm (issue 10: ≤ 0.1 % over ±300 °/s).
pub const SCALE_FACTOR_MAX_PPM: f64 = 1000.0;
/// The ramp's nonlinearity at most this, ppm of full scale (issue 10: ≤ 0.1 % FS).
pub const NONLINEARITY_MAX_PPM_FS: f64 = 1000.0;
/// The sense amplitude "before the drift" is the mean over this long before it starts, s.
pub const AMP_BEFORE_S: f64 = 0.5;
/// The sense amplitude "after the retune" is the mean over the last this long of the run, s.
pub const AMP_AFTER_S: f64 = 1.0;

/// The same verdict numbers for the host-only run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct LoopNumbers {
    /// ω̂y² at the end.
    pub wy2_est: f64,
    /// The estimate converged.
    pub converged: bool,
    /// Retunes the core completed.
    pub retunes: u32,
    /// Sense amplitude after the retune / before the drift.
    pub sense_amp_ratio: f64,
    /// Drive amplitude over the last 1 s / over the 0.5 s before the drift.
    pub drive_amp_ratio: f64,
    /// Samples the core flagged.
    pub bad_ticks: u32,
    /// Pump at the end, Hz.
    pub pump_end_hz: f64,
    /// Rate estimate at the end, °/s.
    pub rate_dps_est: f64,
    /// Mean rate estimate over the last 1 s, °/s (its scale factor against a constant
    /// true rate: the sample's own noise averaged out).
    #[serde(default)]
    pub rate_dps_mean_last_s: f64,
    /// Health bits at the end.
    pub health_end: u32,
    /// The scale factor and nonlinearity of the scenario's ramp leg (`rate-ramp`).
    #[serde(default)]
    pub ramp: Option<RampFit>,
    /// The fast rate's error over the last [`ERR_SPAN_S`] (see [`RateError`]).
    #[serde(default)]
    pub rate_error: Option<RateError>,
    /// A warm-up's figures (`warm-up`), with the rate's own validity flag and the learned
    /// TCFs, which only this loop sees.
    #[serde(default)]
    pub warm_up: Option<WarmUpNumbers>,
    /// The fast rate of every sample, °/s (for `trace.csv`; not in `summary.json`).
    #[serde(skip)]
    pub rates: Vec<f64>,
    /// The drive's lock-in amplitude |x1| of every sample, µm (for `examples/dds_words.rs`;
    /// not in `summary.json`).
    #[serde(skip)]
    pub drive_amps: Vec<f64>,
    /// A warm-up's oracle twin's sense amplitude `(t, |Y1|)` of every sample, µm (its pump
    /// centre at twice the true sense resonance; empty without a warm-up; not in
    /// `summary.json`).
    #[serde(skip)]
    pub oracle_amp: Vec<(f64, f64)>,
}

/// The firmware's fault counters at the end, by name.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FwCounts {
    /// ADC frames lost to SPI errors.
    pub adc_spi_errors: u32,
    /// ADC frames that failed their CRC.
    pub adc_crc_errors: u32,
    /// ADC frames without DRDY flags.
    pub adc_not_ready: u32,
    /// ADC frames with a channel at full scale.
    pub adc_saturated: u32,
    /// Failed accelerometer reads.
    pub accel_errors: u32,
    /// Accelerometer samples at the end of the range.
    pub accel_saturated: u32,
    /// Ticks whose DDS writes failed.
    pub dds_errors: u32,
    /// Commands the guard refused or clamped.
    pub guard_clamps: u32,
    /// DRDY missing (the board's count).
    pub drdy_missing: u32,
    /// The core's bad samples.
    pub core_bad_samples: u32,
    /// Accelerometer samples the firmware refused as stuck.
    pub accel_stuck: u32,
}

/// `target/fil/summary.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Summary {
    /// Scenario name.
    pub scenario: String,
    /// Seed of the plant's noise.
    pub seed: u64,
    /// The pump profile the core was configured with.
    pub core_pump_profile: String,
    /// How the board's DDS moved the pump (`half-steps`, `staircase`,
    /// `staircase-linear`: `session::BoardPump`).
    #[serde(default)]
    pub board_pump: String,
    /// ω̂y² within its tolerance of the truth at the end.
    pub converged: bool,
    /// Retunes the firmware's core completed.
    pub retunes: u32,
    /// Sense amplitude (plant, |Y1|) over the last 1 s / over the 0.5 s before the drift.
    pub sense_amp_ratio: f64,
    /// Drive amplitude (plant, |X1|), same windows.
    pub drive_amp_ratio: f64,
    /// Ticks run.
    pub ticks: u32,
    /// Ticks whose sample the firmware or the core flagged.
    pub bad_ticks: u32,
    /// Exact instructions per tick (mean), the fake chips excluded (QEMU plugin).
    pub instr_mean: f64,
    /// The stack's high-water mark of the `fil` board, bytes (painted, measured).
    pub stack_peak_bytes: u32,
    /// Exact instructions of the costliest tick.
    pub instr_max: u64,
    /// The costliest tick.
    pub instr_max_tick: u32,
    /// SysTick mean of the whole tick, shims included (±6 instructions per tick).
    pub systick_mean_with_shims: f64,
    /// ω̂y² at the end.
    pub wy2_est: f64,
    /// True ωy² at the end.
    pub wy2_true: f64,
    /// Allowed |ω̂y² − ωy²|.
    pub wy2_tol: f64,
    /// Pump the DDS ran at the end, Hz.
    pub pump_end_hz: f64,
    /// IO_UPDATE pulses the AD9959 model saw (set-up included).
    pub io_update_pulses: u64,
    /// Of those, pulses half a period after DRDY (two steps per sample).
    #[serde(default)]
    pub half_period_pulses: u64,
    /// SPI frames the AD9959 model applied (one or more register writes each).
    pub dds_writes: u64,
    /// Ticks after which the DDS's channels were not phase-locked (pump 2k, refs k, 3k).
    pub dds_unlocked_ticks: u64,
    /// The firmware's counters.
    pub fw_counters: FwCounts,
    /// Ticks whose fault bits say the DDS write failed.
    pub dds_fault_ticks: u32,
    /// Ticks whose fault bits say an ADC frame was lost (CRC, not ready, SPI).
    pub adc_fault_ticks: u32,
    /// Rate estimate at the end, °/s.
    pub rate_dps_est: f64,
    /// Mean rate estimate over the last 1 s, °/s.
    #[serde(default)]
    pub rate_dps_mean_last_s: f64,
    /// True rate at the end, °/s.
    pub rate_dps_true: f64,
    /// The core's health bits after the last tick.
    pub health_end: u32,
    /// The scale factor and nonlinearity of the firmware's rate over the scenario's ramp
    /// leg (`rate-ramp`; the host-only loop's in `host_only.ramp`).
    #[serde(default)]
    pub ramp: Option<RampFit>,
    /// The firmware's fast rate's error over the last [`ERR_SPAN_S`], and against the
    /// host-only loop's sample by sample (the host-only loop's own in
    /// `host_only.rate_error`).
    #[serde(default)]
    pub rate_error: Option<RateError>,
    /// A warm-up's figures in the loop (`warm-up`; the host-only loop's in
    /// `host_only.warm_up`).
    #[serde(default)]
    pub warm_up: Option<WarmUpNumbers>,
    /// The firmware's exit code (0: it ended the session cleanly).
    pub exit_code: Option<i32>,
    /// The host-only closed loop of the same scenario (f32 core, same configuration, the
    /// plant's pump a staircase of the core's unquantised commands).
    pub host_only: LoopNumbers,
    /// |ω̂y²(FIL) − ω̂y²(host)| at the end and its tolerance.
    pub wy2_fil_vs_host: f64,
    /// Tolerance of `wy2_fil_vs_host`.
    pub wy2_fil_vs_host_tol: f64,
    /// Every acceptance check held.
    pub pass: bool,
    /// Why not, when `pass` is false.
    pub failures: Vec<String>,
}

/// Start of the first ramp of ωy² or ωx², s (`None`: no drift in the scenario).
pub fn drift_start_s(sc: &Scenario) -> Option<f64> {
    sc.events.iter().find_map(|e| match e.kind {
        EventKind::Ramp {
            param: PlantParam::Wy2 | PlantParam::Wx2,
            ..
        } => Some(e.t_s),
        _ => None,
    })
}

/// Mean of `amp` over `t ∈ [t0, t1)`.
fn mean_over(rows: &[(f64, f64)], t0: f64, t1: f64) -> f64 {
    let (s, n) = rows
        .iter()
        .filter(|(t, _)| *t >= t0 && *t < t1)
        .fold((0.0, 0usize), |(s, n), (_, a)| (s + a, n + 1));
    if n == 0 { f64::NAN } else { s / n as f64 }
}

/// Sense amplitude after / before (NaN without a drift).
pub fn sense_amp_ratio(sc: &Scenario, t_amp: &[(f64, f64)]) -> f64 {
    let Some(t_d) = drift_start_s(sc) else {
        return f64::NAN;
    };
    let before = mean_over(t_amp, t_d - AMP_BEFORE_S, t_d);
    let after = mean_over(t_amp, sc.duration_s - AMP_AFTER_S, f64::INFINITY);
    after / before
}

/// The allowed |ω̂y² − ωy²| at the end.
pub fn wy2_tolerance(sc: &Scenario) -> f64 {
    let w0 = sc.plant_at(0.0).phys[4];
    let w1 = sc.plant_at(sc.duration_s).phys[4];
    let drift = (w1 - w0).abs();
    if drift > 0.0 {
        WY2_TOL_OF_DRIFT * drift
    } else {
        WY2_TOL_NO_DRIFT
    }
}

/// The host-only closed loop: the same scenario and core configuration (f32), the plant's
/// pump shaped as the board's DDS moves it (two steps or one per sample), no
/// quantisation, no SPI.
pub fn host_only(
    sc: &Scenario,
    seed: u64,
    pump: BoardPump,
    leg: Option<RampLeg>,
    words: HostWords,
) -> anyhow::Result<LoopNumbers> {
    host_only_on(sc, seed, pump, leg, WordGrid::of(words))
}

/// [`host_only`] of a loop scenario: its ramp leg, its words and, for a warm-up, its
/// figures ([`WarmUpNumbers`]).
pub fn host_only_of(ls: &LoopScenario, seed: u64, pump: BoardPump) -> anyhow::Result<LoopNumbers> {
    host_only_warm(
        &ls.scenario,
        seed,
        pump,
        ls.ramp,
        WordGrid::of(ls.host_words),
        ls.warm_up,
    )
}

/// [`host_only`] with the pump rounded to the words of `grid` (the board's, or a finer
/// DDS's: `examples/dds_words.rs`).
pub fn host_only_on(
    sc: &Scenario,
    seed: u64,
    pump: BoardPump,
    leg: Option<RampLeg>,
    grid: WordGrid,
) -> anyhow::Result<LoopNumbers> {
    host_only_warm(sc, seed, pump, leg, grid, None)
}

/// [`host_only_on`] with a warm-up's figures.
fn host_only_warm(
    sc: &Scenario,
    seed: u64,
    pump: BoardPump,
    leg: Option<RampLeg>,
    grid: WordGrid,
    warm: Option<WarmUp>,
) -> anyhow::Result<LoopNumbers> {
    let mut sc = sc.clone();
    sc.sim.pump_profile = pump.sim_profile();
    let cfg = crate::session::core_config(&sc, pump.core_profile());
    let mut est: Estimator<f32> = cfg
        .build()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let mut amp = Vec::new();
    let mut damp = Vec::new();
    let mut bad = 0u32;
    let mut last_pump = f64::NAN;
    let mut health_end = 0;
    let mut wy2_true = f64::NAN;
    let mut rates = Vec::new();
    let mut ticks = Vec::new();
    let mut centre_end = f64::NAN;
    let mut words = BoardWords::on_grid(grid, pump);
    runner::closed_loop_hooked(
        &sc,
        seed,
        &runner::Device::default(),
        &mut est,
        &mut words,
        |_| {},
        |ls| {
            amp.push((ls.t_s, ls.lockin.y_abs(1)));
            damp.push((ls.t_s, ls.lockin.x_abs(1)));
            if !ls.out.health.inputs_valid {
                bad += 1;
            }
            last_pump = ls.out.pump_hz_next;
            health_end = ls.out.health.bits();
            wy2_true = ls.plant.phys[4];
            rates.push((ls.t_s, ls.plant.rate_dps, ls.out.rate.rate_dps));
            if warm.is_some() {
                ticks.push(WarmUpTick {
                    t_s: ls.t_s,
                    events: ls.out.events,
                    health: ls.out.health.bits(),
                    rate_valid: Some(ls.out.rate.valid),
                    rate_dps: ls.out.rate.rate_dps,
                    rate_dps_true: ls.plant.rate_dps,
                    pump_hz_next: ls.out.pump_hz_next,
                    wy2_true: ls.plant.phys[4],
                    sense_amp_um: ls.lockin.y_abs(1),
                });
                centre_end = ls.est.pump_centre_hz();
            }
        },
    )?;
    // the oracle twin, on the same plant (the board's pump shape)
    let oracle_amp = match warm {
        Some(_) => paragyro_simulator::thermal::oracle_sense_amp(&sc, seed)?,
        None => Vec::new(),
    };
    let warm_up = warm.map(|w| {
        let mut n = WarmUpNumbers::of(&w, &sc, &ticks, est.counters().retunes)
            .with_oracle(&ticks, &oracle_amp);
        n.pump_centre_core_hz = Some(centre_end);
        n.tcf_learned_ppm_k = Some(est.thermal().tcf_ppm_k);
        n
    });
    let ramp = leg_fit(leg, rates.iter().copied())?;
    let wy2_est = est.wy2();
    Ok(LoopNumbers {
        wy2_est,
        converged: (wy2_est - wy2_true).abs() <= wy2_tolerance(&sc),
        retunes: est.counters().retunes,
        sense_amp_ratio: sense_amp_ratio(&sc, &amp),
        drive_amp_ratio: sense_amp_ratio(&sc, &damp),
        bad_ticks: bad,
        pump_end_hz: last_pump,
        rate_dps_est: est.rate_output().rate_dps,
        rate_dps_mean_last_s: mean_last_s(&sc, rates.iter().map(|r| (r.0, r.2))),
        health_end,
        ramp,
        rate_error: RateError::of(&sc, &rates, None),
        warm_up,
        rates: rates.iter().map(|r| r.2).collect(),
        drive_amps: damp.iter().map(|d| d.1).collect(),
        oracle_amp,
    })
}

/// The fit of `leg` on `(t, true rate, estimate)` (`None` without a leg).
fn leg_fit(
    leg: Option<RampLeg>,
    rates: impl Iterator<Item = (f64, f64, f64)>,
) -> anyhow::Result<Option<RampFit>> {
    let Some(leg) = leg else { return Ok(None) };
    let on_leg = rates
        .filter(|r| r.0 >= leg.from_s && r.0 < leg.to_s)
        .map(|r| (r.1, r.2));
    Ok(Some(ramp_fit(on_leg, leg.full_scale_dps)?))
}

/// Which of the board's DDS words the host-only loop's pump takes ([`BoardWords`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HostWords {
    /// The amplitude's 10-bit words.
    pub amplitude: bool,
    /// The frequency's words, two steps per sample with error feedback.
    pub frequency: bool,
}

/// The AD9959's amplitude words, bits (`AmplitudeWord::FULL` is `2^10 − 1`: test).
pub const BOARD_AMPLITUDE_BITS: u32 = 10;

/// The resolution of the words the host-only loop's pump is rounded to ([`BoardWords`]):
/// the board's ([`WordGrid::of`]) or another DDS's, to price each word's part of the rate's
/// error (`examples/dds_words.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WordGrid {
    /// The amplitude's words, bits (10: the AD9959's, its own `AmplitudeWord::from_scale`;
    /// more: `round((2^bits − 1)·√(m/full_scale))`); `None`: not rounded.
    pub amplitude_bits: Option<u32>,
    /// The frequency's words, as the DDS's SYSCLK that makes them, Hz (a pump word is
    /// `2·f_SYSCLK/2³²`: the board's 125 MHz, `ad9959::DEFAULT_SYSCLK_HZ`, makes 0.058 Hz);
    /// `None`: not rounded.
    pub frequency_sysclk_hz: Option<f64>,
}

impl WordGrid {
    /// The board's words where `words` asks for them.
    pub fn of(words: HostWords) -> Self {
        WordGrid {
            amplitude_bits: words.amplitude.then_some(BOARD_AMPLITUDE_BITS),
            frequency_sysclk_hz: words.frequency.then_some(DEFAULT_SYSCLK_HZ),
        }
    }
}

/// The host-only loop's pump as the board's DDS makes it ([`HostWords`], or the words of
/// any [`WordGrid`]; hooks that change nothing when both are off).
///
/// * Amplitude: the core's multiplier `m` of the scenario's pump scale becomes the
///   AD9959's amplitude word, `ASF = round(1023·√(m/full_scale))` (the force goes with the
///   voltage squared; the board's own `ad9959::AmplitudeWord::from_scale`), and the plant and the next
///   sample take `(ASF/1023)²·full_scale`: one word is 0.24 % of the scale at `m` = 1.
/// * Frequency (two steps per sample): the command's reference word and the two steps
///   towards it from the last command's, whole words with error feedback
///   (`paragyro_firmware::app::half_steps`, the board's function); the plant steps to them
///   (the simulator's half steps are the quarter points of its interval, so the interval
///   runs over the sweep whose half means they are, (3a − b)/2 → (3b − a)/2 words), the
///   next sample reports that sweep's end and the core is told its move, 2(b − a) words
///   (`Estimator::set_pump_sweep_hz`), as the board's `App::tell_steps`.
pub struct BoardWords {
    /// The amplitude's full scale and bits, with the words.
    amplitude_full_scale: Option<(f64, u32)>,
    /// Hz per pump word (`paragyro_firmware::run::pump_step_hz` on the board), with the words.
    frequency_hz_per_word: Option<f64>,
    node: Option<i32>,
    residual: i32,
    sweep_hz: Option<f64>,
}

impl BoardWords {
    /// The hooks for the board's `words` (the frequency's only with the board's two steps).
    pub fn new(words: HostWords, pump: BoardPump) -> Self {
        Self::on_grid(WordGrid::of(words), pump)
    }

    /// The hooks for the words of `grid` (the frequency's only with the board's two steps).
    pub fn on_grid(grid: WordGrid, pump: BoardPump) -> Self {
        let full = f64::from(paragyro_firmware::run::AMPLITUDE.full_scale);
        BoardWords {
            amplitude_full_scale: grid.amplitude_bits.map(|b| (full, b.clamp(1, 30))),
            frequency_hz_per_word: grid
                .frequency_sysclk_hz
                .filter(|f| *f > 0.0 && pump == BoardPump::HalfSteps)
                .map(|f| 2.0 * f / FTW_SCALE),
            node: None,
            residual: 0,
            sweep_hz: None,
        }
    }

    /// The multiplier `m` as the amplitude words give it (`m` itself without them).
    pub fn round_amplitude(&self, m: f64) -> f64 {
        let Some((full, bits)) = self.amplitude_full_scale else {
            return m;
        };
        let top = f64::from((1u32 << bits) - 1);
        let word = if bits == BOARD_AMPLITUDE_BITS {
            // the board's own word for the scale `m/full_scale`
            f64::from(AmplitudeWord::from_scale((m / full) as f32).get())
        } else {
            (top * (m / full).clamp(0.0, 1.0).sqrt()).round()
        };
        (word / top).powi(2) * full
    }
}

impl runner::LoopHooks<f32> for BoardWords {
    fn step(
        &mut self,
        _k: u64,
        est: &mut Estimator<f32>,
        sample: &mut paragyro_core::Sample<f32>,
        _last: &paragyro_core::StepOutput,
    ) -> paragyro_core::StepOutput {
        if let Some(sweep) = self.sweep_hz.take() {
            est.set_pump_sweep_hz(sweep as f32);
        }
        est.step(sample)
    }

    fn inputs(
        &mut self,
        _k: u64,
        u0: &mut paragyro_simulator::plant::PlantInputs,
        u1: &mut paragyro_simulator::plant::PlantInputs,
        next: &mut (f64, f64),
    ) {
        if self.amplitude_full_scale.is_some() && next.1 > 0.0 {
            let m = self.round_amplitude(next.1);
            u1.s *= m / next.1;
            next.1 = m;
        }
        if let Some(hpw) = self.frequency_hz_per_word
            && next.0 > 0.0
        {
            let per_hz = u1.omega / next.0;
            let c = (next.0 / hpw).round() as i32;
            let node = self.node.unwrap_or(c);
            let (a, b, residual) = paragyro_firmware::app::half_steps(node, c, self.residual);
            let (a, b) = (f64::from(a), f64::from(b));
            u0.omega = 0.5 * (3.0 * a - b) * hpw * per_hz;
            u1.omega = 0.5 * (3.0 * b - a) * hpw * per_hz;
            next.0 = 0.5 * (3.0 * b - a) * hpw;
            self.sweep_hz = Some(2.0 * (b - a) * hpw);
            self.node = Some(c);
            self.residual = residual;
        }
    }
}

/// The span at the end over which [`RateError`] is read, s.
pub const ERR_SPAN_S: f64 = 2.0;

/// The fast rate's error over the last [`ERR_SPAN_S`] of a run whose true rate is constant
/// there (`None` otherwise): its mean and rms about that mean against the truth, every
/// sample (valid or not), and — for the firmware — the rms about its mean of its
/// difference from the host-only loop's rate, sample by sample, which isolates what the
/// firmware's path (its drivers, the chips' words, the DDS's steps) adds.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RateError {
    /// Mean of estimate − truth, °/s.
    pub mean_dps: f64,
    /// Rms of estimate − truth about its mean, °/s.
    pub rms_dps: f64,
    /// Rms about its mean of the firmware's rate − the host-only loop's, °/s (firmware
    /// only).
    #[serde(default)]
    pub vs_host_only_rms_dps: Option<f64>,
}

impl RateError {
    /// From `(t, truth, estimate)` per sample and, for the firmware, the host-only loop's
    /// estimate of the same samples.
    fn of(sc: &Scenario, rows: &[(f64, f64, f64)], host: Option<&[f64]>) -> Option<Self> {
        let from = sc.duration_s - ERR_SPAN_S;
        let k0 = rows.iter().position(|r| r.0 >= from)?;
        let span = &rows[k0..];
        let truth = span.first()?.1;
        if span.len() < 100 || span.iter().any(|r| r.1 != truth) {
            return None;
        }
        let mean_rms = |v: &mut dyn Iterator<Item = f64>| {
            let v: Vec<f64> = v.collect();
            let m = v.iter().sum::<f64>() / v.len() as f64;
            let r = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
            (m, r)
        };
        let (mean_dps, rms_dps) = mean_rms(&mut span.iter().map(|r| r.2 - r.1));
        let vs_host_only_rms_dps = host
            .filter(|h| h.len() == rows.len())
            .map(|h| mean_rms(&mut span.iter().zip(&h[k0..]).map(|(r, h)| r.2 - h)).1);
        Some(RateError {
            mean_dps,
            rms_dps,
            vs_host_only_rms_dps,
        })
    }
}

/// The mean of `(t, v)` over the scenario's last second.
fn mean_last_s(sc: &Scenario, rows: impl Iterator<Item = (f64, f64)>) -> f64 {
    let from = sc.duration_s - 1.0;
    let (n, sum) = rows
        .filter(|(t, _)| *t >= from)
        .fold((0u32, 0.0), |(n, s), (_, v)| (n + 1, s + v));
    sum / f64::from(n)
}

/// What the scenario expects of the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Expect {
    /// At least one retune, and the sense amplitude back (ratio ≥ 1).
    pub retune: bool,
    /// Ticks the faults may flag (0: every sample valid).
    pub max_bad_ticks: u32,
    /// The rate estimate at the end within [`RATE_TOL_FRAC`] of the truth.
    pub rate: bool,
    /// The drive falls out of its band: the drive's amplitude must fall below
    /// [`DRIVE_LOST_RATIO`] of its start, the core must flag it (`drive_locked` cleared at
    /// the end, in the loop and in the host-only loop), no retune, no guard clamp, and the
    /// pump at the end within [`PUMP_FIL_VS_HOST_HZ`] of the host-only loop's (the rate
    /// is not compared: without a drive there is none).
    pub out_of_band: bool,
}

/// The drive is lost when its amplitude at the end is below this fraction of its
/// amplitude before the drift.
pub const DRIVE_LOST_RATIO: f64 = 0.5;
/// `Health::bits` bit of `drive_locked`.
pub const DRIVE_LOCKED_BIT: u32 = 1 << 4;
/// The pump at the end, loop against host-only: the DDS's quantisation plus the `f32`
/// commands' differences; four pump words of a 500 MHz SYSCLK (0.93 Hz), sixteen of the
/// board's 125 MHz.
pub const PUMP_FIL_VS_HOST_HZ: f64 = 0.94;

/// The summary of a session against the host-only loop.
pub fn summarize(
    ls: &LoopScenario,
    seed: u64,
    pump: BoardPump,
    s: &Session,
    host: LoopNumbers,
) -> Summary {
    let (sc, expect, faults, leg) = (&ls.scenario, ls.expect, &ls.faults, ls.ramp);
    let end = &s.end;
    let c = end.counters;
    let wy2_est = end.wy2;
    let wy2_true = s.rows.last().map_or(f64::NAN, |r| r.wy2_true);
    let wy2_tol = wy2_tolerance(sc);
    let converged = (wy2_est - wy2_true).abs() <= wy2_tol;
    let amp: Vec<(f64, f64)> = s.rows.iter().map(|r| (r.t_s, r.sense_amp_um)).collect();
    let ratio = sense_amp_ratio(sc, &amp);
    let damp: Vec<(f64, f64)> = s.rows.iter().map(|r| (r.t_s, r.drive_amp_um)).collect();
    let drive_ratio = sense_amp_ratio(sc, &damp);
    let bad = s
        .rows
        .iter()
        .filter(|r| !(r.fw.sample_ok && r.fw.inputs_valid))
        .count() as u32;
    let n = s.instructions.len().max(1) as f64;
    let instr_mean = s.instructions.iter().sum::<u64>() as f64 / n;
    let (imax_k, imax) = s
        .instructions
        .iter()
        .enumerate()
        .max_by_key(|(_, v)| **v)
        .map_or((0, 0), |(k, v)| (k as u32, *v));
    let systick_mean = s
        .rows
        .iter()
        .map(|r| f64::from(r.fw.tick_insns))
        .sum::<f64>()
        / s.rows.len().max(1) as f64;
    let vs_host = (wy2_est - host.wy2_est).abs();
    let vs_host_tol = if wy2_tol == WY2_TOL_NO_DRIFT {
        WY2_TOL_NO_DRIFT
    } else {
        WY2_FIL_VS_HOST_OF_DRIFT * wy2_tol / WY2_TOL_OF_DRIFT
    };
    let rate_est = end.rate_dps;
    let rate_true = s.rows.last().map_or(f64::NAN, |r| r.rate_dps_true);
    let mut failures = Vec::new();
    loop_checks(
        &mut failures,
        &LoopFacts {
            expect,
            converged,
            wy2: (wy2_est, wy2_true, wy2_tol),
            vs_host: (vs_host, vs_host_tol),
            ratio,
            bad,
            rate: (rate_est, rate_true),
        },
        s,
        &host,
    );
    let ramp = ramp_checks(&mut failures, leg, s);
    let (dds_fault_ticks, adc_fault_ticks) = fault_checks(&mut failures, faults, s);
    let warm_up = ls.warm_up.map(|w| {
        let ticks: Vec<WarmUpTick> = s
            .rows
            .iter()
            .map(|r| WarmUpTick {
                t_s: r.t_s,
                events: r.fw.events,
                health: r.fw.health,
                rate_valid: Some(r.fw.rate_valid),
                rate_dps: r.fw.rate_dps,
                rate_dps_true: r.rate_dps_true,
                pump_hz_next: r.fw.pump_hz_next,
                wy2_true: r.wy2_true,
                sense_amp_um: r.sense_amp_um,
            })
            .collect();
        let n = WarmUpNumbers::of(&w, sc, &ticks, c[9]).with_oracle(&ticks, &host.oracle_amp);
        warm_up_checks(&mut failures, &w, &n, host.warm_up.as_ref());
        n
    });
    Summary {
        scenario: sc.name.clone(),
        seed,
        core_pump_profile: format!("{:?}", pump.core_profile()),
        board_pump: pump.name().to_string(),
        converged,
        retunes: c[9],
        sense_amp_ratio: ratio,
        drive_amp_ratio: drive_ratio,
        ticks: s.rows.len() as u32,
        bad_ticks: bad,
        instr_mean,
        stack_peak_bytes: end.stack_peak,
        instr_max: imax,
        instr_max_tick: imax_k,
        systick_mean_with_shims: systick_mean,
        wy2_est,
        wy2_true,
        wy2_tol,
        pump_end_hz: s.rows.last().map_or(f64::NAN, |r| r.dds_pump_hz),
        io_update_pulses: s.pulses,
        half_period_pulses: s.half_period_pulses,
        dds_writes: s.dds_writes,
        dds_unlocked_ticks: s.unlocked_ticks,
        fw_counters: fw_counts(&c),
        dds_fault_ticks,
        adc_fault_ticks,
        rate_dps_est: rate_est,
        rate_dps_mean_last_s: mean_last_s(sc, s.rows.iter().map(|r| (r.t_s, r.fw.rate_dps))),
        rate_dps_true: rate_true,
        health_end: s.rows.last().map_or(0, |r| r.fw.health),
        ramp,
        rate_error: RateError::of(
            sc,
            &s.rows
                .iter()
                .map(|r| (r.t_s, r.rate_dps_true, r.fw.rate_dps))
                .collect::<Vec<_>>(),
            Some(&host.rates),
        ),
        warm_up,
        exit_code: s.exit_code,
        host_only: host,
        wy2_fil_vs_host: vs_host,
        wy2_fil_vs_host_tol: vs_host_tol,
        pass: failures.is_empty(),
        failures,
    }
}

/// The numbers [`loop_checks`] judges, computed by [`summarize`].
struct LoopFacts {
    expect: Expect,
    converged: bool,
    /// ω̂y² at the end, the true ωy², the tolerance.
    wy2: (f64, f64, f64),
    /// |ω̂y²(FIL) − ω̂y²(host)| and its tolerance.
    vs_host: (f64, f64),
    /// Sense amplitude after the retune / before the drift.
    ratio: f64,
    bad: u32,
    /// The rate estimate at the end and the true rate, °/s.
    rate: (f64, f64),
}

/// The loop's own checks and those against the host-only loop; failures appended.
fn loop_checks(failures: &mut Vec<String>, f: &LoopFacts, s: &Session, host: &LoopNumbers) {
    let mut check = |ok: bool, what: String| {
        if !ok {
            failures.push(what);
        }
    };
    let (expect, converged, ratio, bad) = (f.expect, f.converged, f.ratio, f.bad);
    let (wy2_est, wy2_true, wy2_tol) = f.wy2;
    let (vs_host, vs_host_tol) = f.vs_host;
    let (rate_est, rate_true) = f.rate;
    let c = s.end.counters;
    check(
        converged,
        format!("ω̂y² {wy2_est} vs {wy2_true} (tolerance {wy2_tol:.3e})"),
    );
    if expect.retune {
        check(c[9] >= 1, "the firmware did not retune".into());
        check(
            ratio >= 1.0,
            format!("sense amplitude ratio {ratio:.4} < 1"),
        );
    }
    check(
        bad <= expect.max_bad_ticks,
        format!("{bad} bad ticks (allowed {})", expect.max_bad_ticks),
    );
    check(
        s.instructions.len() == s.rows.len(),
        format!(
            "{} instruction counts for {} ticks",
            s.instructions.len(),
            s.rows.len()
        ),
    );
    check(
        s.exit_code == Some(0),
        format!("firmware exit code {:?}", s.exit_code),
    );
    check(
        s.unlocked_ticks == 0,
        format!(
            "{} ticks with the DDS channels not phase-locked",
            s.unlocked_ticks
        ),
    );
    check(
        host.converged == converged,
        format!("host-only converged {} vs loop {converged}", host.converged),
    );
    check(
        vs_host <= vs_host_tol,
        format!("|ω̂y²(FIL) − ω̂y²(host)| {vs_host:.3e} > {vs_host_tol:.3e}"),
    );
    if expect.retune {
        check(
            host.retunes >= 1 && host.sense_amp_ratio >= 1.0,
            "the host-only loop did not retune".into(),
        );
    }
    if expect.rate {
        let tol = RATE_TOL_FRAC * rate_true.abs();
        check(
            (rate_est - rate_true).abs() <= tol,
            format!("rate {rate_est:.4} °/s vs {rate_true:.4} (tolerance {tol:.3})"),
        );
    }
    let tol = RATE_FIL_VS_HOST_FRAC * rate_true.abs();
    // without a drive there is no rate to compare (out of band)
    check(
        expect.out_of_band || (rate_est - host.rate_dps_est).abs() <= tol,
        format!(
            "rate {rate_est:.4} °/s vs host-only {:.4} (tolerance {tol:.3})",
            host.rate_dps_est
        ),
    );
}

/// The ramp leg's fit (scale factor, nonlinearity) and its checks; failures appended.
fn ramp_checks(failures: &mut Vec<String>, leg: Option<RampLeg>, s: &Session) -> Option<RampFit> {
    let rows = s
        .rows
        .iter()
        .map(|r| (r.t_s, r.rate_dps_true, r.fw.rate_dps));
    let ramp = match leg_fit(leg, rows) {
        Ok(fit) => fit,
        Err(e) => {
            failures.push(format!("the ramp leg: {e}"));
            None
        }
    };
    if let Some(f) = ramp {
        let mut check = |ok: bool, what: String| {
            if !ok {
                failures.push(what);
            }
        };
        check(
            f.scale_factor_err_ppm.abs() <= SCALE_FACTOR_MAX_PPM,
            format!(
                "scale-factor error {:.0} ppm over the ramp (at most {SCALE_FACTOR_MAX_PPM:.0})",
                f.scale_factor_err_ppm
            ),
        );
        check(
            f.nonlinearity_ppm_fs <= NONLINEARITY_MAX_PPM_FS,
            format!(
                "nonlinearity {:.0} ppm FS over the ramp (at most {NONLINEARITY_MAX_PPM_FS:.0})",
                f.nonlinearity_ppm_fs
            ),
        );
    }
    ramp
}

/// Every injected fault flagged and counted, none elsewhere; failures appended. Returns the
/// ticks with a DDS fault and those with a lost ADC frame.
fn fault_checks(failures: &mut Vec<String>, faults: &Faults, s: &Session) -> (u32, u32) {
    let mut check = |ok: bool, what: String| {
        if !ok {
            failures.push(what);
        }
    };
    let c = s.end.counters;
    let fault = |bit: u8| s.rows.iter().filter(move |r| r.fw.faults & bit != 0);
    use paragyro_firmware::app::fault;
    let dds_fault_ticks = fault(fault::DDS).count() as u32;
    let adc_fault_ticks = fault(fault::ADC_X | fault::ADC_Y).count() as u32;
    let span_len = |sp: paragyro_firmware::replay::Span| {
        sp.end.min(s.rows.len()).saturating_sub(sp.start) as u32
    };
    check(
        c[1] == span_len(faults.crc),
        format!(
            "{} CRC errors counted for {} injected",
            c[1],
            span_len(faults.crc)
        ),
    );
    check(
        c[8] == span_len(faults.no_drdy) && c[2] == 2 * span_len(faults.no_drdy),
        format!(
            "missing DRDY: {} counted, {} frames not ready, for {} injected",
            c[8],
            c[2],
            span_len(faults.no_drdy)
        ),
    );
    let in_span = |sp: paragyro_firmware::replay::Span, bit: u8| {
        s.rows
            .iter()
            .enumerate()
            .filter(|(_, r)| r.fw.faults & bit != 0)
            .all(|(k, _)| sp.contains(k))
    };
    check(
        c[6] == dds_fault_ticks
            && in_span(faults.dds_fail, fault::DDS)
            && (dds_fault_ticks > 0) == (span_len(faults.dds_fail) > 0),
        format!(
            "{} DDS errors counted, {dds_fault_ticks} ticks flagged",
            c[6]
        ),
    );
    // a stuck accelerometer is refused from its ACCEL_STUCK_READS-th identical read on
    let stuck = span_len(faults.stuck_accel)
        .saturating_sub(paragyro_firmware::fil::ACCEL_STUCK_READS.saturating_sub(1));
    check(
        c[11] == stuck && c[4] == 0,
        format!(
            "{} stuck accelerometer samples counted, {stuck} expected",
            c[11]
        ),
    );
    check(
        adc_fault_ticks == span_len(faults.crc) + span_len(faults.no_drdy),
        format!("{adc_fault_ticks} ticks with a lost ADC frame"),
    );
    (dds_fault_ticks, adc_fault_ticks)
}

/// The firmware's counters by name.
fn fw_counts(c: &[u32]) -> FwCounts {
    FwCounts {
        adc_spi_errors: c[0],
        adc_crc_errors: c[1],
        adc_not_ready: c[2],
        adc_saturated: c[3],
        accel_errors: c[4],
        accel_saturated: c[5],
        dds_errors: c[6],
        guard_clamps: c[7],
        drdy_missing: c[8],
        core_bad_samples: c[10],
        accel_stuck: c[11],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The host-only loop's amplitude words are the AD9959's: the word of the multiplier,
    /// squared and scaled back; m = 1 is word 818 (0.8·1023 = 818.4), 0.1 % low.
    #[test]
    fn the_host_only_amplitude_words_are_the_dds_words() {
        let words = HostWords {
            amplitude: true,
            frequency: false,
        };
        let w = BoardWords::new(words, BoardPump::HalfSteps);
        let full = f64::from(paragyro_firmware::run::AMPLITUDE.full_scale);
        let want = (818.0f64 / 1023.0).powi(2) * 1.5625;
        assert!((w.round_amplitude(1.0) - want).abs() < 1e-15);
        for m in [0.3, 0.9, 1.0, 1.07, 1.1] {
            let word =
                paragyro_firmware::drivers::ad9959::AmplitudeWord::from_scale((m / full) as f32);
            let dds = f64::from(word.get()) / 1023.0;
            assert!(
                (w.round_amplitude(m) - dds * dds * full).abs() < 1e-12,
                "{m}"
            );
        }
        assert_eq!(w.round_amplitude(9.0), full);
        let off = BoardWords::new(HostWords::default(), BoardPump::HalfSteps);
        assert_eq!(off.round_amplitude(1.0), 1.0);
    }

    /// The board's grid is the board's words, and a finer amplitude grid rounds to its own
    /// words: 12 bits within half a 12-bit word of the exact scale.
    #[test]
    fn a_word_grid_is_the_boards_at_the_boards_resolution_and_finer_above_it() {
        assert_eq!(
            (1u32 << BOARD_AMPLITUDE_BITS) - 1,
            u32::from(AmplitudeWord::FULL.get())
        );
        let both = HostWords {
            amplitude: true,
            frequency: true,
        };
        let grid = WordGrid::of(both);
        assert_eq!(grid.amplitude_bits, Some(10));
        assert_eq!(grid.frequency_sysclk_hz, Some(DEFAULT_SYSCLK_HZ));
        let board = BoardWords::new(both, BoardPump::HalfSteps);
        let on = BoardWords::on_grid(grid, BoardPump::HalfSteps);
        let fine = BoardWords::on_grid(
            WordGrid {
                amplitude_bits: Some(12),
                frequency_sysclk_hz: Some(DEFAULT_SYSCLK_HZ / 4.0),
            },
            BoardPump::HalfSteps,
        );
        let full = f64::from(paragyro_firmware::run::AMPLITUDE.full_scale);
        let mut worst_board: f64 = 0.0;
        for k in 0..200 {
            let m = 0.9 + 0.001 * f64::from(k);
            assert_eq!(board.round_amplitude(m), on.round_amplitude(m));
            // in words of the root: |√(m'/full) − √(m/full)| ≤ half a word
            let word = |x: f64| (x / full).sqrt();
            let e12 = (word(fine.round_amplitude(m)) - word(m)).abs() * 4095.0;
            assert!(e12 <= 0.5 + 1e-9, "{m}: {e12}");
            worst_board =
                worst_board.max((word(board.round_amplitude(m)) - word(m)).abs() * 4095.0);
        }
        assert!(
            worst_board > 1.0,
            "the board's words are coarser: {worst_board}"
        );
        let hpw = paragyro_firmware::run::pump_step_hz();
        assert_eq!(board.frequency_hz_per_word, Some(hpw));
        assert_eq!(fine.frequency_hz_per_word, Some(hpw / 4.0));
    }

    /// With the frequency words the plant's two steps are the board's whole words and the
    /// next sample reports the end of the sweep whose half means they are, near the
    /// command.
    #[test]
    fn the_host_only_frequency_words_step_as_the_boards() {
        use paragyro_simulator::plant::PlantInputs;
        use runner::LoopHooks;
        let words = HostWords {
            amplitude: false,
            frequency: true,
        };
        let mut w = BoardWords::new(words, BoardPump::HalfSteps);
        let hpw = paragyro_firmware::run::pump_step_hz();
        let f0 = 10_960.0;
        let mut next = (0.0, 1.0);
        let mk = |hz: f64| PlantInputs {
            omega: hz / (2.0 * f0),
            s: 1.0,
            ax: 0.0,
            ay: 0.0,
        };
        for k in 0..50u32 {
            let cmd = 21_900.0 + 0.3 * hpw + f64::from(k) * 1.7 * hpw;
            next.0 = cmd;
            let (mut u0, mut u1) = (mk(cmd), mk(cmd));
            LoopHooks::<f32>::inputs(&mut w, u64::from(k), &mut u0, &mut u1, &mut next);
            // the quarter points are whole words
            for q in [0.25, 0.75] {
                let step = (u0.omega + (u1.omega - u0.omega) * q) * 2.0 * f0 / hpw;
                assert!((step - step.round()).abs() < 1e-6, "{k}: {step}");
            }
            assert!((next.0 - u1.omega * 2.0 * f0).abs() < 1e-6);
            assert!(
                (next.0 - cmd).abs() < 2.0 * hpw,
                "{k}: {} for {cmd}",
                next.0
            );
        }
        assert!(w.sweep_hz.is_some());
        let off = BoardWords::new(words, BoardPump::Staircase);
        assert!(off.frequency_hz_per_word.is_none());
    }

    /// A run whose last 2 s hold a constant truth gives the error's mean and rms and the
    /// firmware's rms against the host-only loop's; a truth that moves there gives none.
    #[test]
    fn the_rate_error_is_read_over_a_constant_truth_only() {
        let mut sc = Scenario::builtin("drift-retune").unwrap();
        sc.duration_s = 4.0;
        let rows: Vec<(f64, f64, f64)> = (0..2000)
            .map(|k| {
                let t = f64::from(k) * 0.002;
                // ±0.3 alternating about an offset of 0.1
                (t, 150.0, 150.1 + if k % 2 == 0 { 0.3 } else { -0.3 })
            })
            .collect();
        let host: Vec<f64> = rows.iter().map(|r| r.2 - 0.05).collect();
        let e = RateError::of(&sc, &rows, Some(&host)).unwrap();
        assert!((e.mean_dps - 0.1).abs() < 1e-9, "{e:?}");
        assert!((e.rms_dps - 0.3).abs() < 1e-9, "{e:?}");
        assert!(e.vs_host_only_rms_dps.unwrap() < 1e-9, "{e:?}");
        let mut moving = rows.clone();
        moving[1500].1 = 151.0;
        assert_eq!(RateError::of(&sc, &moving, None), None);
        // a host-only trace of another length is not compared
        let e = RateError::of(&sc, &rows, Some(&host[1..])).unwrap();
        assert_eq!(e.vs_host_only_rms_dps, None);
    }
}
