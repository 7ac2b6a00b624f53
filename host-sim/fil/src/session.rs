//! One firmware-in-the-loop session: QEMU running the `fil` board, the host playing the
//! chips from the full-rate plant, one exchange per 500 Hz tick.

use std::fs::{self, File, OpenOptions};
use std::io::{ErrorKind, Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use paragyro_core::config::PumpProfile;
use paragyro_firmware::drivers::adxl355::Range;
use paragyro_firmware::fil::{
    FROM_FW_BYTES, FromFw, Init, MAX_TICK_CONTROLS, TICK_END, TICK_SETUP, ToFw, flag, init_flag,
};
use paragyro_firmware::run::{AMPLITUDE, GUARD_HALF_WIDTH_HZ};
use paragyro_firmware::table::{config_slots, control};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::plant::{GyroSim, PlantInputs, SimConfig, Theta};
use paragyro_simulator::runner;
use paragyro_simulator::scenario::{EventKind, L0_M, PlantAt, PumpProfileSpec, Scenario};

use crate::chips::{Dds, Faults, SensorChips};

/// µm per volt of the drive and sense lock-in channels at the ADC (PGA gain 1): the
/// design scale of the replay table and of the stm32f405 board.
pub const UM_PER_VOLT: [f32; 2] = [8.0, 4.0];
/// ADXL355 range bits: ±8 g.
pub const ACCEL_RANGE_BITS: u32 = 3;
/// How long the host waits for one answer of the firmware.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);
/// O_NONBLOCK on Linux.
const O_NONBLOCK: i32 = 0o4000;

/// What to run.
#[derive(Clone, Debug)]
pub struct Options {
    /// The scenario (name or path).
    pub scenario: Scenario,
    /// Overrides the scenario's seed.
    pub seed: Option<u64>,
    /// Faults to inject.
    pub faults: Faults,
    /// How the board's DDS moves between commands and what the core is told.
    pub pump: BoardPump,
    /// The firmware image (a `fil` build).
    pub elf: PathBuf,
    /// The instruction-count plugin (`libtickcount.so`).
    pub plugin: PathBuf,
    /// Working directory of the session (pipes, logs).
    pub work_dir: PathBuf,
}

/// How the board's DDS moves between two 500 Hz commands, and the pump profile its core
/// is configured with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BoardPump {
    /// Two steps per sample, 1/4 and 3/4 of the way (IO_UPDATE at the tick and half a
    /// period after DRDY, `App::set_half_steps`); the core's linear replica. The
    /// stm32f405 and `fil` boards.
    HalfSteps,
    /// One step per sample, at the tick; the core told `Staircase` (ZOH replica).
    Staircase,
    /// One step per sample; the core told `Linear` (the mismatch, kept as a measurement).
    StaircaseLinear,
}

impl BoardPump {
    /// The core's pump profile.
    pub fn core_profile(self) -> PumpProfile {
        match self {
            BoardPump::HalfSteps => PumpProfile::HalfSteps,
            BoardPump::StaircaseLinear => PumpProfile::Linear,
            BoardPump::Staircase => PumpProfile::Staircase,
        }
    }

    /// Whether the board pulses IO_UPDATE a second time, half a period after DRDY.
    pub fn half_steps(self) -> bool {
        self == BoardPump::HalfSteps
    }

    /// The host-only loop's pump (the DDS's shape, unquantised).
    pub fn sim_profile(self) -> PumpProfileSpec {
        if self.half_steps() {
            PumpProfileSpec::HalfSteps
        } else {
            PumpProfileSpec::Staircase
        }
    }

    /// Its name on the command line and in the summary.
    pub fn name(self) -> &'static str {
        match self {
            BoardPump::HalfSteps => "half-steps",
            BoardPump::Staircase => "staircase",
            BoardPump::StaircaseLinear => "staircase-linear",
        }
    }
}

/// One tick as the host saw it.
#[derive(Clone, Copy, Debug)]
pub struct TickRow {
    /// Time, s.
    pub t_s: f64,
    /// True ωy².
    pub wy2_true: f64,
    /// True rate, °/s.
    pub rate_dps_true: f64,
    /// The plant's sense amplitude |Y1|, µm.
    pub sense_amp_um: f64,
    /// The plant's drive amplitude |X1|, µm.
    pub drive_amp_um: f64,
    /// The pump the DDS ran over the interval after this tick, Hz.
    pub dds_pump_hz: f64,
    /// The firmware's answer.
    pub fw: FromFw,
}

/// The raw outcome of a session.
pub struct Session {
    /// Every tick.
    pub rows: Vec<TickRow>,
    /// The answer to the end message (final counters).
    pub end: FromFw,
    /// Exact instructions per tick without the fake chips (the plugin), one per tick.
    pub instructions: Vec<u64>,
    /// IO_UPDATE pulses the AD9959 model saw.
    pub pulses: u64,
    /// Of those, pulses half a period after DRDY (the second of two steps).
    pub half_period_pulses: u64,
    /// SPI frames (transactions) the AD9959 model applied, each of one or more register
    /// writes.
    pub dds_writes: u64,
    /// Ticks after which the DDS's three channels were not phase-locked (2k, k, 3k).
    pub unlocked_ticks: u64,
    /// The firmware's exit code.
    pub exit_code: Option<i32>,
}

/// The control events of the interval `(t, t_next]` as the firmware's control kinds.
fn controls_for(
    sc: &Scenario,
    events: &[paragyro_simulator::scenario::EventSpec],
    next: &mut usize,
    t_next: f64,
) -> anyhow::Result<Vec<(u32, f64)>> {
    let mut out = Vec::new();
    while *next < events.len() && events[*next].t_s <= t_next + 1e-12 {
        let e = events[*next];
        match e.kind {
            EventKind::PumpJump { .. } => {
                if let Some(c) = sc.pump_jump_centre_hz(&e) {
                    out.push((control::PUMP_JUMP_HZ, c));
                }
            }
            EventKind::Dither { enabled, pump_hz } => {
                if let Some(a) = pump_hz {
                    out.push((control::DITHER_PUMP_HZ, a));
                }
                out.push((control::DITHER, if enabled { 1.0 } else { 0.0 }));
            }
            EventKind::Retune { enabled } => {
                out.push((control::RETUNE, if enabled { 1.0 } else { 0.0 }))
            }
            _ => {}
        }
        *next += 1;
    }
    ensure!(
        out.len() <= MAX_TICK_CONTROLS,
        "more than {MAX_TICK_CONTROLS} control events in one tick at {t_next} s"
    );
    Ok(out)
}

/// The QEMU process and the pipes to it; killed on drop if still running.
struct Qemu {
    child: Child,
    to_fw: File,
    from_fw: mpsc::Receiver<std::io::Result<Vec<u8>>>,
}

impl Drop for Qemu {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

impl Qemu {
    fn send(&mut self, bytes: &[u8]) -> anyhow::Result<()> {
        let mut done = 0;
        let t0 = Instant::now();
        while done < bytes.len() {
            match self.to_fw.write(&bytes[done..]) {
                Ok(n) => done += n,
                Err(e)
                    if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted =>
                {
                    self.alive()?;
                    ensure!(
                        t0.elapsed() < ANSWER_TIMEOUT,
                        "the firmware does not read its pipe"
                    );
                    std::thread::sleep(Duration::from_micros(50));
                }
                Err(e) => return Err(e).context("writing to the firmware"),
            }
        }
        Ok(())
    }

    fn alive(&mut self) -> anyhow::Result<()> {
        if let Some(st) = self.child.try_wait()? {
            bail!("QEMU exited early ({st}); see qemu.log and defmt.log in the work directory");
        }
        Ok(())
    }

    fn recv(&mut self) -> anyhow::Result<FromFw> {
        let t0 = Instant::now();
        loop {
            match self.from_fw.recv_timeout(Duration::from_millis(200)) {
                Ok(Ok(b)) => {
                    let arr: [u8; FROM_FW_BYTES] =
                        b.try_into().map_err(|_| anyhow::anyhow!("short answer"))?;
                    return Ok(FromFw::decode(&arr));
                }
                Ok(Err(e)) => return Err(e).context("reading the firmware's answer"),
                Err(mpsc::RecvTimeoutError::Timeout) => {
                    self.alive()?;
                    ensure!(
                        t0.elapsed() < ANSWER_TIMEOUT,
                        "no answer from the firmware in {ANSWER_TIMEOUT:?}"
                    );
                }
                Err(mpsc::RecvTimeoutError::Disconnected) => {
                    self.alive()?;
                    bail!("the firmware closed its pipe");
                }
            }
        }
    }
}

fn mkfifo(p: &Path) -> anyhow::Result<()> {
    let st = Command::new("mkfifo")
        .arg(p)
        .status()
        .context("running mkfifo")?;
    ensure!(st.success(), "mkfifo {} failed", p.display());
    Ok(())
}

fn start_qemu(opts: &Options, markers: [u32; 4]) -> anyhow::Result<Qemu> {
    let dir = &fs::canonicalize(&opts.work_dir)?;
    let elf = fs::canonicalize(&opts.elf)?;
    let plugin_so = fs::canonicalize(&opts.plugin)?;
    let run = dir.join("run");
    if run.exists() {
        fs::remove_dir_all(&run).with_context(|| format!("removing {}", run.display()))?;
    }
    fs::create_dir_all(&run)?;
    let to_path = run.join("fil_to_fw");
    let from_path = run.join("fil_from_fw");
    mkfifo(&to_path)?;
    mkfifo(&from_path)?;
    let [b, e, fi, fo] = markers;
    // PARAGYRO_FIL_HIST_TICK=K: the histogram of tick K alone (fil-profile.sh)
    let only = std::env::var("PARAGYRO_FIL_HIST_TICK")
        .ok()
        .and_then(|k| k.parse::<u64>().ok())
        .map_or(String::new(), |k| format!(",only={k}"));
    let plugin = format!(
        "{}{only},begin={b:x},end={e:x},fin={fi:x},fout={fo:x},out={},hist={}",
        plugin_so.display(),
        dir.join("tickcount.txt").display(),
        dir.join("tickhist.txt").display()
    );
    let child = Command::new("qemu-system-arm")
        .current_dir(&run)
        .args([
            "-cpu",
            "cortex-m4",
            "-machine",
            "netduinoplus2",
            "-nographic",
        ])
        .args(["-monitor", "none", "-serial", "none", "-icount", "shift=0"])
        .args(["-semihosting-config", "enable=on,target=native"])
        .args(["-plugin", &plugin, "-d", "plugin", "-D"])
        .arg(dir.join("plugin.log"))
        .arg("-kernel")
        .arg(&elf)
        .stdin(Stdio::null())
        .stdout(File::create(dir.join("defmt.bin"))?)
        .stderr(File::create(dir.join("qemu.log"))?)
        .spawn()
        .context("starting qemu-system-arm (install it: `cargo xtask setup`)")?;
    // same order as the firmware: fil_to_fw first (it reads), then fil_from_fw
    let t0 = Instant::now();
    let mut child = child;
    let to_fw = loop {
        match OpenOptions::new()
            .write(true)
            .custom_flags(O_NONBLOCK)
            .open(&to_path)
        {
            Ok(f) => break f,
            Err(e) if e.raw_os_error() == Some(6) => {
                // ENXIO: the firmware has not opened its end yet
                if let Some(st) = child.try_wait()? {
                    bail!(
                        "QEMU exited before opening the pipes ({st}); see {}",
                        dir.join("qemu.log").display()
                    );
                }
                if t0.elapsed() > ANSWER_TIMEOUT {
                    let _ = child.kill();
                    bail!("the firmware did not open fil_to_fw");
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => return Err(e).context("opening fil_to_fw"),
        }
    };
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut f = match File::open(&from_path) {
            Ok(f) => f,
            Err(e) => {
                let _ = tx.send(Err(e));
                return;
            }
        };
        loop {
            let mut b = vec![0u8; FROM_FW_BYTES];
            match f.read_exact(&mut b) {
                Ok(()) => {
                    if tx.send(Ok(b)).is_err() {
                        return;
                    }
                }
                Err(e) if e.kind() == ErrorKind::UnexpectedEof => return,
                Err(e) => {
                    let _ = tx.send(Err(e));
                    return;
                }
            }
        }
    });
    Ok(Qemu {
        child,
        to_fw,
        from_fw: rx,
    })
}

/// The core configuration the firmware gets for `sc` with the pump profile `profile`.
pub fn core_config(sc: &Scenario, profile: PumpProfile) -> paragyro_core::Config {
    let mut cfg = runner::core_config(sc);
    cfg.pump_profile = profile;
    cfg
}

/// Runs the session.
pub fn run(opts: &Options) -> anyhow::Result<Session> {
    let sc = &opts.scenario;
    let cfg = core_config(sc, opts.pump.core_profile());
    cfg.validated()
        .map_err(|e| anyhow::anyhow!("core configuration: {e}"))?;
    let elf = fs::read(&opts.elf).with_context(|| format!("reading {}", opts.elf.display()))?;
    let markers = crate::elf::markers(&elf)?;
    fs::create_dir_all(&opts.work_dir)?;
    let init = Init {
        cfg_slots: config_slots(&cfg),
        um_per_volt: UM_PER_VOLT,
        accel_range_bits: ACCEL_RANGE_BITS,
        flags: if opts.pump.half_steps() {
            init_flag::HALF_STEPS
        } else {
            0
        },
        guard_half_width_hz: GUARD_HALF_WIDTH_HZ,
        amplitude: [AMPLITUDE.base_scale, AMPLITUDE.full_scale],
    };
    let mut q = start_qemu(opts, markers)?;
    q.send(&init.encode())?;
    let setup = q.recv()?;
    ensure!(
        setup.tick == TICK_SETUP,
        "unexpected set-up answer (tick {})",
        setup.tick
    );
    let mut dds = Dds::new();
    let mut pulses = u64::from(dds.apply(&setup)?.0);
    let mut half_pulses = 0u64;
    ensure!(
        pulses > 0,
        "the firmware did not start the pump (no IO_UPDATE at set-up)"
    );

    let seed = opts.seed.unwrap_or(sc.seed);
    let w0 = sc.omega0_rad_s();
    let fs = cfg.fs_hz;
    // two steps per sample: the plant advances in half intervals, each with its pump
    let halves = if opts.pump.half_steps() { 2 } else { 1 };
    let simcfg = sim_config(sc, &cfg, halves, seed);
    let x0 = [sc.plant.initial_x_um, 0.0, sc.plant.initial_y_um, 0.0];
    let mut sim = GyroSim::new(&simcfg, x0).map_err(|e| anyhow::anyhow!("simulator: {e}"))?;
    let n = (sc.duration_s * fs).round() as u64;
    let accel_si = L0_M * w0 * w0;
    let events = sc.control_events();
    let mut next_ev = 0usize;
    let mut chips = SensorChips::new(UM_PER_VOLT, Range::G8, opts.faults, seed).with_temp_noise(
        sc.temperature
            .as_ref()
            .filter(|t| t.sensor)
            .map_or(0.0, |t| t.sensor_noise_k),
    );
    let mut rows = Vec::with_capacity(n as usize + 1);
    let mut unlocked = 0u64;
    for k in 0..=n {
        let ku = k as usize;
        let t = k as f64 / fs;
        let t_next = (k + 1) as f64 / fs;
        let ctl = controls_for(sc, &events, &mut next_ev, t_next)?;
        let pa = sc.plant_at(t);
        let li = sim.lockin();
        let mut controls = [(0u32, 0.0f64); MAX_TICK_CONTROLS];
        controls[..ctl.len()].copy_from_slice(&ctl);
        let mut flags = 0;
        if !chips.drdy(ku) {
            flags |= flag::NO_DRDY;
        }
        if chips.dds_fails(ku) {
            flags |= flag::DDS_FAIL;
        }
        let msg = ToFw {
            tick: k as u32,
            flags,
            controls,
            n_controls: ctl.len() as u8,
            adc: chips.adc_frames(ku, &li.to_channels()),
            accel: chips.accel_burst(
                ku,
                pa.accel_x * accel_si,
                pa.accel_y * accel_si,
                sc.temp_c(t),
            ),
        };
        q.send(&msg.encode())?;
        let fw = q.recv()?;
        ensure!(
            fw.tick == k as u32,
            "answer for tick {} at tick {k}",
            fw.tick
        );
        let (p, first_half) = dds.apply(&fw)?;
        pulses += u64::from(p);
        half_pulses += u64::from(first_half.is_some());
        if !dds.phase_locked() {
            unlocked += 1;
        }
        rows.push(TickRow {
            t_s: t,
            wy2_true: pa.phys[4],
            rate_dps_true: pa.rate_dps,
            sense_amp_um: li.y_abs(1),
            drive_amp_um: li.x_abs(1),
            dds_pump_hz: dds.pump_hz(),
            fw,
        });
        if k == n {
            break;
        }
        advance_plant(opts, &mut sim, &dds, &pa, t_next, first_half);
    }
    let (end, exit_code, instructions) = finish(&mut q, opts)?;
    Ok(Session {
        rows,
        end,
        instructions,
        pulses,
        half_period_pulses: half_pulses,
        dds_writes: dds.writes,
        unlocked_ticks: unlocked,
        exit_code,
    })
}

/// The simulator's configuration for a session: `halves` plant steps per sample.
fn sim_config(sc: &Scenario, cfg: &paragyro_core::Config, halves: u32, seed: u64) -> SimConfig {
    let f0 = sc.sim.f0_hz;
    SimConfig {
        omega0_rad_s: sc.omega0_rad_s(),
        fs_hz: cfg.fs_hz * f64::from(halves),
        steps_per_period: sc.sim.steps_per_period,
        omega_max: (cfg.pump_centre_hz + GUARD_HALF_WIDTH_HZ) / (2.0 * f0) * 1.01,
        lpf_order: sc.sim.lockin_lpf_order,
        lpf_hz: sc.sim.lockin_lpf_hz,
        noise_density: sc.sim.noise_pm_rthz * 1e-6,
        seed,
    }
}

/// Advances the plant over one sample interval from `pa` (the plant at its start) to
/// `t_next` under the DDS's words.
fn advance_plant(
    opts: &Options,
    sim: &mut GyroSim,
    dds: &Dds,
    pa: &PlantAt,
    t_next: f64,
    first_half: Option<(f64, f64)>,
) {
    let sc = &opts.scenario;
    let f0 = sc.sim.f0_hz;
    // the DDS steps at IO_UPDATE and holds: the plant sees the new word over the
    // whole interval (a staircase), or with two steps the first word over the first
    // half and the second over the second (the first pulse's delay after DRDY, the
    // tick's length, is not modelled)
    let pa1 = sc.plant_at(t_next);
    let theta = Theta {
        drive: pa.theta_drive,
        sense: pa.theta_sense,
    };
    let full = f64::from(AMPLITUDE.full_scale) * sc.pump_scale_at(t_next);
    let second = (dds.pump_hz(), dds.pump_word_scale());
    let input = |(hz, word_scale): (f64, f64), ax: f64, ay: f64| PlantInputs {
        omega: hz / (2.0 * f0),
        s: word_scale * full,
        ax,
        ay,
    };
    let (u0, u1) = (
        input(second, pa.accel_x, pa.accel_y),
        input(second, pa1.accel_x, pa1.accel_y),
    );
    if opts.pump.half_steps() {
        let first = input(first_half.unwrap_or(second), 0.0, 0.0);
        let first = (first.omega, first.s);
        runner::advance_in_halves(sim, &theta, &u0, &u1, first, (u1.omega, u1.s));
    } else {
        sim.advance(&theta, &u0, &u1);
    }
}

/// Sends the end message, waits for QEMU to exit and reads the plugin's instruction
/// counts: the end answer, QEMU's exit code, the instructions per tick.
fn finish(q: &mut Qemu, opts: &Options) -> anyhow::Result<(FromFw, Option<i32>, Vec<u64>)> {
    let end_msg = ToFw {
        tick: u32::MAX,
        flags: flag::END,
        controls: [(0, 0.0); MAX_TICK_CONTROLS],
        n_controls: 0,
        adc: [[0; paragyro_firmware::drivers::ads131m08::FRAME_BYTES]; 2],
        accel: [0; paragyro_firmware::fil::ACCEL_BURST],
    };
    q.send(&end_msg.encode())?;
    let end = q.recv()?;
    ensure!(end.tick == TICK_END, "unexpected end answer");
    let t0 = Instant::now();
    let exit_code = loop {
        if let Some(st) = q.child.try_wait()? {
            break st.code();
        }
        ensure!(
            t0.elapsed() < ANSWER_TIMEOUT,
            "QEMU did not exit after the end message"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    let counts = fs::read_to_string(opts.work_dir.join("tickcount.txt"))
        .context("the instruction-count plugin wrote no tickcount.txt")?;
    let instructions = counts
        .lines()
        .map(|l| l.trim().parse::<u64>())
        .collect::<Result<Vec<_>, _>>()
        .context("tickcount.txt")?;
    Ok((end, exit_code, instructions))
}
