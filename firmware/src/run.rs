//! The replay run of the QEMU board, as a library so that the host runs the very same
//! code (tests/tests/firmware_qemu.rs compares the two tick by tick).
//!
//! [`replay_app`] builds the board from a [`ReplayTable`]: both ADS131M08s, the ADXL355
//! and the AD9959 are replay devices ([`crate::replay`]) behind the real drivers, each
//! chip is initialised by its driver as on the real board, and the [`App`] is started.
//! Each tick then runs [`App::tick_with_pump`] with the record's pump (open-loop replay:
//! the recorded lock-in data were produced by that pump), and [`ReplayCheck`] follows the
//! outputs: a digest of every tick's outputs, the DDS command against the record's next
//! pump, and at the end the verdict ([`ReplayCheck::verdict`]): the estimate converged to
//! the simulation's truth and the retune moved the pump to the new sense resonance.

use embedded_hal::delay::DelayNs;
use paragyro_core::ConfigError;

use crate::app::{App, Chips, PumpAmplitude, PumpGuard, TickReport};
use crate::drivers::ad9959::{Ad9959, DEFAULT_SYSCLK_HZ, FTW_SCALE};
use crate::drivers::ads131m08::{self, Ads131m08, Gain, LOCKIN_CHANNELS, LockinCalibration};
use crate::drivers::adxl355::{Adxl355, HighPass, Odr, Range};
use crate::replay::{CaptureDds, CaptureIo, DdsCapture, ReplayAccel, ReplayAdc};
use crate::table::{ReplayTable, control, truth};

/// The application over the replay devices.
pub type ReplayApp<'a> = App<ReplayAdc<'a>, ReplayAdc<'a>, ReplayAccel<'a>, CaptureDds<'a>>;

/// Half-width of the pump guard around the configured centre, Hz: the retune of the scenario moves the centre by 37 Hz and the dither adds
/// ±21.6 Hz, so the guard never acts in a good run; it is the last line against a runaway
/// command, not the scheduler (a clamp would show in the fault bits and fail the run).
pub const GUARD_HALF_WIDTH_HZ: f64 = 400.0;

/// Amplitude mapping of the replay board: `s_base` = 1 and the full DDS word at
/// `s` = 1.5625 (1.25 V_A0), room above the +10 % amplitude dither.
pub const AMPLITUDE: PumpAmplitude = PumpAmplitude {
    base_scale: 1.0,
    full_scale: 1.5625,
};

/// The ω̂y² check: |ω̂y² − ωy²| at the end at most this fraction of the drift
/// |ωy²(end) − ωy²(start)| (the estimate must have followed the drift, not stayed put).
pub const WY2_TOL_OF_DRIFT: f64 = 0.1;

/// The retune check: the pump the firmware commands at the end must be within this
/// fraction of the expected move (pump centre at the start → the new sense resonance
/// 2·√ωy²·f0) of the new resonance.
pub const RETUNE_TOL_OF_MOVE: f64 = 0.1;

/// The DDS check: after every tick the pump the DDS runs must be the record's next pump
/// (the host's f64 closed loop) to within half a pump word step (the quantisation) plus
/// this much, Hz, for the difference between the `f32` and the `f64` core's commands
/// (measured on `fw-drift-retune`: 2.1e-5 Hz beyond the half step).
pub const DDS_F32_MARGIN_HZ: f64 = 0.01;

/// A pump word step of the AD9959 (the pump word is twice the reference word): Hz.
pub fn pump_step_hz() -> f64 {
    2.0 * DEFAULT_SYSCLK_HZ / FTW_SCALE
}

/// Why the replay board could not be set up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SetupError {
    /// The table's configuration (or the guard) was rejected.
    Config(ConfigError),
    /// An ADS131M08 init failed (0 drive, 1 sense).
    Adc(u8),
    /// The ADXL355 init failed, or the table's range is not one the driver knows.
    Accel,
    /// The AD9959 init or the first pump command failed.
    Dds,
}

/// The calibration of one axis: `um_per_volt` µm per volt at the ADC input, PGA gain 1,
/// no offset (what the table's codes were made with).
pub fn calibration(um_per_volt: f32) -> LockinCalibration {
    LockinCalibration::from_um_per_volt(
        [um_per_volt; LOCKIN_CHANNELS],
        [Gain::G1; LOCKIN_CHANNELS],
        [0; LOCKIN_CHANNELS],
    )
}

fn range_of(bits: u32) -> Option<Range> {
    match bits {
        1 => Some(Range::G2),
        2 => Some(Range::G4),
        3 => Some(Range::G8),
        _ => None,
    }
}

/// The replay board's chips: [`ReplayApp`]'s.
pub type ReplayChips<'a> = Chips<ReplayAdc<'a>, ReplayAdc<'a>, ReplayAccel<'a>, CaptureDds<'a>>;

/// Builds the replay board over `table`, initialises the chips through their drivers,
/// creates the [`App`] with the table's configuration and starts the pump (through `io`,
/// the DDS capture's IO_UPDATE line): [`replay_chips`], [`App::unconfigured`] and
/// [`configure_replay`], which the qemu board calls one by one so that its App is built
/// in its final place.
pub fn replay_app<'a, D: DelayNs>(
    table: ReplayTable<'a>,
    dds: &'a DdsCapture,
    io: &mut CaptureIo<'a>,
    delay: &mut D,
) -> Result<ReplayApp<'a>, SetupError> {
    let mut app = App::unconfigured(replay_chips(table, dds, delay)?);
    configure_replay(&mut app, table, io)?;
    Ok(app)
}

/// The replay devices over `table` behind the real drivers, initialised.
#[inline(never)]
pub fn replay_chips<'a, D: DelayNs>(
    table: ReplayTable<'a>,
    dds: &'a DdsCapture,
    delay: &mut D,
) -> Result<ReplayChips<'a>, SetupError> {
    let mut adc_x = Ads131m08::new(ReplayAdc::from_table(table, 0));
    let mut adc_y = Ads131m08::new(ReplayAdc::from_table(table, 1));
    adc_x
        .init(delay, &ads131m08::Config::PARAGYRO)
        .map_err(|_| SetupError::Adc(0))?;
    adc_y
        .init(delay, &ads131m08::Config::PARAGYRO)
        .map_err(|_| SetupError::Adc(1))?;
    let mut accel = Adxl355::new(ReplayAccel::from_table(table));
    let range = range_of(table.accel_range_bits()).ok_or(SetupError::Accel)?;
    accel
        .init(range, Odr::Hz500, HighPass::Off)
        .map_err(|_| SetupError::Accel)?;
    let mut dds_drv = Ad9959::new(dds.spi(), DEFAULT_SYSCLK_HZ);
    dds_drv.init().map_err(|_| SetupError::Dds)?;
    Ok(Chips {
        adc_x,
        adc_y,
        accel,
        dds: dds_drv,
    })
}

/// Configures `app` with the table's configuration, calibrations and guard (the
/// estimator designed in place, [`App::configure`]), sets the replay's amplitude mapping
/// and starts the pump. Never inlined: the design's temporaries live in this call only.
#[inline(never)]
pub fn configure_replay<'a>(
    app: &mut ReplayApp<'a>,
    table: ReplayTable<'a>,
    io: &mut CaptureIo<'a>,
) -> Result<(), SetupError> {
    let cfg = table.config();
    let cal_x = calibration(table.um_per_volt_x());
    let cal_y = calibration(table.um_per_volt_y());
    let guard = PumpGuard::around(cfg.pump_centre_hz, GUARD_HALF_WIDTH_HZ);
    app.configure(&cfg, cal_x, cal_y, guard)
        .map_err(SetupError::Config)?;
    app.set_pump_amplitude(AMPLITUDE)
        .map_err(SetupError::Config)?;
    app.start(io).map_err(|_| SetupError::Dds)?;
    Ok(())
}

/// Gives the core the table's control events listed for tick `k` (before the tick, as
/// the simulator's closed loop did). Returns how many were applied.
pub fn apply_controls(table: &ReplayTable<'_>, k: usize, app: &mut ReplayApp<'_>) -> usize {
    let mut n = 0usize;
    for i in 0..table.controls() {
        let Some(c) = table.control(i) else { continue };
        if c.tick as usize != k {
            continue;
        }
        let est = app.estimator_mut();
        match c.kind {
            control::DITHER => est.set_dither(c.value != 0.0),
            // a refused value (out of range) changes nothing, as the core documents
            control::DITHER_PUMP_HZ => {
                let _ = est.set_dither_pump_hz(c.value);
            }
            control::RETUNE => est.set_retune(c.value != 0.0),
            control::PUMP_JUMP_HZ => {
                let _ = est.command_pump_centre(c.value, true);
            }
            _ => continue,
        }
        n = n.saturating_add(1);
    }
    n
}

pub use crate::table::Fnv64;

/// Hashes one tick's outputs: the core's command and health, the firmware's realised
/// pump and fault bits, and θ̂ (`Estimator::theta`, the bits of its `f64` values).
pub fn digest_tick<AX, AY, XL, DDS>(h: &mut Fnv64, app: &App<AX, AY, XL, DDS>, r: &TickReport)
where
    AX: embedded_hal::spi::SpiDevice,
    AY: embedded_hal::spi::SpiDevice,
    XL: embedded_hal::spi::SpiDevice,
    DDS: embedded_hal::spi::SpiDevice,
{
    h.write(&r.out.pump_hz_next.to_bits().to_le_bytes());
    h.write(&r.out.pump_scale_next.to_bits().to_le_bytes());
    h.write(&r.out.health.bits().to_le_bytes());
    h.write(&[r.out.events, u8::from(r.out.updated), r.faults]);
    h.write(&r.pump_hz.to_bits().to_le_bytes());
    h.write(&r.pump_scale.to_bits().to_le_bytes());
    let (t1, t2) = app.estimator().theta();
    for v in t1.iter().chain(t2.iter()) {
        h.write(&v.to_bits().to_le_bytes());
    }
}

/// The outcome of a replay run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verdict {
    /// Ticks run.
    pub ticks: u32,
    /// Ticks whose sample the firmware or the core flagged.
    pub bad_ticks: u32,
    /// Digest of every tick's outputs ([`digest_tick`]).
    pub digest: u64,
    /// ω̂y² at the end and the truth.
    pub wy2_est: f64,
    /// True ωy² at the end.
    pub wy2_true: f64,
    /// Allowed |ω̂y² − ωy²|.
    pub wy2_tol: f64,
    /// Realised pump at the end (the DDS's active word), Hz.
    pub pump_end_hz: f64,
    /// The new sense resonance, Hz.
    pub resonance_end_hz: f64,
    /// Allowed |pump − resonance| at the end, Hz.
    pub pump_tol_hz: f64,
    /// Retunes the core completed.
    pub retunes: u32,
    /// Largest |DDS pump after tick k − record pump at k+1| over the run, Hz.
    pub dds_vs_record_max_hz: f64,
    /// Same, over the ticks after the dither was switched off (the steady part), Hz.
    pub dds_vs_record_steady_max_hz: f64,
    /// Rate estimate at the end, °/s.
    pub rate_dps: f64,
}

impl Verdict {
    /// The estimate converged (ω̂y² within its tolerance of the truth).
    pub fn converged(&self) -> bool {
        (self.wy2_est - self.wy2_true).abs() <= self.wy2_tol
    }

    /// The retune happened and took the pump to the new resonance.
    pub fn retuned(&self) -> bool {
        self.retunes > 0 && (self.pump_end_hz - self.resonance_end_hz).abs() <= self.pump_tol_hz
    }

    /// The DDS ran the record's pump (up to the quantisation, [`DDS_F32_MARGIN_HZ`]).
    pub fn dds_tracks_record(&self) -> bool {
        self.dds_vs_record_max_hz <= 0.5 * pump_step_hz() + DDS_F32_MARGIN_HZ
    }

    /// Every sample valid, converged, retuned, the DDS on the record's pump.
    pub fn pass(&self) -> bool {
        self.bad_ticks == 0 && self.converged() && self.retuned() && self.dds_tracks_record()
    }
}

/// Follows a replay run tick by tick.
#[derive(Clone, Copy, Debug)]
pub struct ReplayCheck {
    digest: Fnv64,
    ticks: u32,
    bad: u32,
    dds_max: f64,
    dds_steady_max: f64,
    fs_hz: f64,
    dither_off_s: f64,
}

impl ReplayCheck {
    /// Nothing seen yet, for a run over `table`.
    pub fn new(table: &ReplayTable<'_>) -> Self {
        Self {
            digest: Fnv64::default(),
            ticks: 0,
            bad: 0,
            dds_max: 0.0,
            dds_steady_max: 0.0,
            fs_hz: table.cfg_slot(crate::table::cfg::FS_HZ),
            dither_off_s: table.truth(truth::DITHER_OFF_S),
        }
    }

    /// The digest so far.
    pub fn digest(&self) -> u64 {
        self.digest.0
    }

    /// After tick `k` of `table`: digest, validity, DDS against the record's pump at
    /// `k + 1` (`dds_pump_hz`: the pump the DDS runs after this tick's IO_UPDATE).
    pub fn observe(
        &mut self,
        table: &ReplayTable<'_>,
        k: usize,
        app: &ReplayApp<'_>,
        r: &TickReport,
        dds_pump_hz: f64,
    ) {
        digest_tick(&mut self.digest, app, r);
        self.ticks = self.ticks.saturating_add(1);
        if !(r.sample_ok && r.out.health.inputs_valid) {
            self.bad = self.bad.saturating_add(1);
        }
        if let Some((next, _)) = k.checked_add(1).and_then(|j| table.pump(j)) {
            let d = (dds_pump_hz - next).abs();
            // NaN compares false: a NaN deviation must not hide
            if d.is_nan() || d > self.dds_max {
                self.dds_max = d;
            }
            let t = k as f64 / self.fs_hz;
            if t >= self.dither_off_s && (d.is_nan() || d > self.dds_steady_max) {
                self.dds_steady_max = d;
            }
        }
    }

    /// The verdict at the end of the run.
    pub fn verdict(
        &self,
        table: &ReplayTable<'_>,
        app: &ReplayApp<'_>,
        dds_pump_hz: f64,
    ) -> Verdict {
        let w0 = table.truth(truth::WY2_START);
        let w1 = table.truth(truth::WY2_END);
        let p0 = table.truth(truth::PUMP_CENTRE_START_HZ);
        let p1 = table.truth(truth::SENSE_RESONANCE_END_HZ);
        Verdict {
            ticks: self.ticks,
            bad_ticks: self.bad,
            digest: self.digest.0,
            wy2_est: app.estimator().wy2(),
            wy2_true: w1,
            wy2_tol: WY2_TOL_OF_DRIFT * (w1 - w0).abs(),
            pump_end_hz: dds_pump_hz,
            resonance_end_hz: p1,
            pump_tol_hz: RETUNE_TOL_OF_MOVE * (p1 - p0).abs(),
            retunes: app.estimator().counters().retunes,
            dds_vs_record_max_hz: self.dds_max,
            dds_vs_record_steady_max_hz: self.dds_steady_max,
            rate_dps: app.estimator().rate_output().rate_dps,
        }
    }
}
