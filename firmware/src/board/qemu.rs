//! The QEMU board (`netduinoplus2`, the STM32F405's core and memory map, no SPI chips).
//!
//! The chips are replay devices serving the firmware's replay table
//! (`firmware/replay/fw-drift-retune.bin`: ≥ 10 s of the `fw-drift-retune` scenario,
//! simulated on the host by `paragyro-fw-replay table`), and the AD9959 is a capture of
//! what the firmware writes. The run ([`paragyro_firmware::run`], the same library code
//! the host test runs):
//!
//! 1. every chip is initialised by its real driver over its replay device, the [`App`] is
//!    built from the table's core configuration and the pump started;
//! 2. each tick gives the core the table's control events for that tick (dither off at
//!    6 s, as the simulator did), then runs [`App::tick_with_pump`] with the record's pump
//!    (open-loop replay: the recorded frames were produced by that pump), timed with
//!    SysTick (exact instruction counts under `-icount shift=0`);
//! 3. after each tick the per-tick outputs go into a digest, the DDS's realised pump is
//!    compared with the record's next pump, and every 50 ticks a telemetry line is
//!    printed (10 Hz);
//! 4. the verdict: every sample valid, ω̂y² within 10 % of the drift of the true ωy²,
//!    a retune that took the pump within 10 % of the expected move of the new sense
//!    resonance, the DDS on the record's pump within the word quantisation. Exit 0 only
//!    then; 1 on a failed check, a panic or a HardFault (main.rs); the runner's timeout
//!    turns a hang into 124.
//!
//! Features: `tick-stream` prints every tick's outputs (`TICK` lines, for the host
//! comparison test), `capture` every tick's inputs (`CAP` lines, the capture mode).
//!
//! Profile mode (firmware/scripts/fw-profile.sh): built with `PARAGYRO_PROFILE_TICKS=N` in the
//! environment, the board sets up as usual, then runs only the first `N` ticks (control
//! events and `tick_with_pump`, nothing else: no checks, no telemetry) and exits 0, so
//! that a per-address instruction histogram of an `N`-tick run minus that of a 0-tick run
//! is exactly the ticks' instructions.
//!
//! [`App`]: paragyro_firmware::app::App
//! [`App::tick_with_pump`]: paragyro_firmware::app::App::tick_with_pump

use super::stack::{paint_stack, stack_bounds, stack_high_water};
use cortex_m::peripheral::{SYST, syst::SystClkSource};
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::debug;
use defmt_semihosting as _;
use embedded_hal::delay::DelayNs;
use paragyro_firmware::app::App;
use paragyro_firmware::drivers::ad9959::DEFAULT_SYSCLK_HZ;
use paragyro_firmware::replay::DdsCapture;
use paragyro_firmware::run::{self, ReplayCheck};
use paragyro_firmware::table::{ReplayTable, cfg};

/// The replay table (see the module documentation).
static TABLE: &[u8] = include_bytes!("../../replay/fw-drift-retune.bin");

/// SysTick runs at the core clock (168 MHz on netduinoplus2); with `-icount shift=0`
/// QEMU advances 1 ns per instruction, so instructions = ticks · 1e9 / 168e6.
const SYSTICK_HZ: u64 = 168_000_000;
/// The tick budget, instructions (the run counts the ticks above it).
const TICK_BUDGET_INSNS: u64 = 20_000;

/// The replay chips answer at once: no wait is needed (the real board waits).
struct NoWait;

impl DelayNs for NoWait {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// Stack painting: the free RAM between the end of the statics (`_stack_end`) and the
/// current stack pointer is filled with this word at boot; the lowest word that no longer
/// holds it after the run gives the stack's high-water mark.
#[entry]
fn main() -> ! {
    paint_stack();
    let ok = match cortex_m::Peripherals::take() {
        Some(mut cp) => replay(&mut cp.SYST),
        None => false,
    };
    defmt::info!("{}", if ok { "PASS" } else { "FAIL" });
    exit(ok)
}

fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}

fn replay(syst: &mut SYST) -> bool {
    let table = match ReplayTable::parse(TABLE) {
        Ok(t) => t,
        Err(e) => {
            defmt::error!("replay table: {}", e);
            return false;
        }
    };
    let fs_hz = table.cfg_slot(cfg::FS_HZ);
    defmt::info!(
        "paragyro-firmware, qemu board: replaying {=usize} samples ({=f64} s) of fw-drift-retune, table FNV-1a 64 {=u64:x}",
        table.len(),
        table.len() as f64 / fs_hz,
        table.hash()
    );
    let dds = DdsCapture::new(DEFAULT_SYSCLK_HZ);
    let mut io = dds.io_update();
    // the App is built in its final place (blank estimator, every field a constant) and
    // the estimator designed into it: no estimator- or App-sized temporary on the stack
    let chips = match run::replay_chips(table, &dds, &mut NoWait) {
        Ok(c) => c,
        Err(e) => {
            defmt::error!("board setup failed: {}", defmt::Debug2Format(&e));
            return false;
        }
    };
    let mut app = App::unconfigured(chips);
    if let Err(e) = run::configure_replay(&mut app, table, &mut io) {
        defmt::error!("board setup failed: {}", defmt::Debug2Format(&e));
        return false;
    }
    let app = &mut app;
    #[cfg(feature = "capture")]
    super::capture_header(&table.config());
    if let Some(n) = option_env!("PARAGYRO_PROFILE_TICKS") {
        let n = n.parse::<usize>().unwrap_or(0).min(table.len());
        for k in 0..n {
            run::apply_controls(&table, k, app);
            let Some((pump_hz, pump_scale)) = table.pump(k) else {
                return false;
            };
            let _ = app.tick_with_pump(&mut io, pump_hz, pump_scale);
        }
        defmt::info!("profile mode: {=usize} ticks run", n);
        return true;
    }

    let setup_stack = stack_high_water();
    // repaint: from here on the high-water mark is the tick loop's
    paint_stack();
    let loop_sp = cortex_m::register::msp::read() as usize;

    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();
    let mut check = ReplayCheck::new(&table);
    let mut costs = TickCosts::new();
    for k in 0..table.len() {
        run::apply_controls(&table, k, app);
        let Some((pump_hz, pump_scale)) = table.pump(k) else {
            return false;
        };
        let t0 = SYST::get_current();
        let r = app.tick_with_pump(&mut io, pump_hz, pump_scale);
        let t1 = SYST::get_current();
        costs.observe(t0.wrapping_sub(t1) & 0x00FF_FFFF, k);
        check.observe(&table, k, app, &r, dds.active_pump_hz());
        #[cfg(feature = "tick-stream")]
        {
            let (t1, t2) = app.estimator().theta();
            defmt::info!(
                "TICK k={=usize} cmd={=f64} pump={=f64} scale={=f64} h={=u32} ev={=u8} f={=u8} d={=u64:x} t1={} t2={}",
                k,
                r.out.pump_hz_next,
                r.pump_hz,
                r.out.pump_scale_next,
                r.out.health.bits(),
                r.out.events,
                r.faults,
                check.digest(),
                t1,
                t2
            );
        }
        #[cfg(feature = "capture")]
        super::capture_tick(k as u32, app);
        if (k as u32).is_multiple_of(super::TELEMETRY_EVERY) {
            super::telemetry(k as u32, fs_hz, app, &r);
        }
    }
    costs.log(table.len());
    let loop_stack = stack_high_water();
    let (_, stack_top) = stack_bounds();
    defmt::info!(
        "stack high-water mark: set-up {=usize} B, tick loop {=usize} B = the board's frame {=usize} B (holding the App, {=usize} B) + {=usize} B below it (tick, checks, telemetry)",
        setup_stack,
        loop_stack,
        stack_top - loop_sp,
        core::mem::size_of::<run::ReplayApp<'static>>(),
        loop_stack.saturating_sub(stack_top - loop_sp)
    );
    let v = check.verdict(&table, app, dds.active_pump_hz());
    defmt::info!("core counters: {}", app.estimator().counters());
    defmt::info!("firmware counters: {}", app.counters());
    log_verdict(&v);
    v.pass()
}

/// SysTick cost of every tick (instructions under `-icount shift=0`): mean, worst, the
/// five costliest and the number over the budget.
struct TickCosts {
    total: u64,
    worst: u32,
    worst_k: usize,
    top: [(u32, usize); 5],
    budget: u32,
    over_budget: u32,
}

impl TickCosts {
    fn new() -> Self {
        TickCosts {
            total: 0,
            worst: 0,
            worst_k: 0,
            top: [(0, 0); 5],
            budget: (TICK_BUDGET_INSNS * SYSTICK_HZ / 1_000_000_000) as u32,
            over_budget: 0,
        }
    }

    /// Tick `k` took `dt` SysTick counts.
    fn observe(&mut self, dt: u32, k: usize) {
        self.total += u64::from(dt);
        if dt > self.worst {
            self.worst = dt;
            self.worst_k = k;
        }
        self.over_budget += u32::from(dt > self.budget);
        let top = &mut self.top;
        if dt > top[top.len() - 1].0 {
            let mut i = top.len() - 1;
            top[i] = (dt, k);
            while i > 0 && top[i].0 > top[i - 1].0 {
                top.swap(i, i - 1);
                i -= 1;
            }
        }
    }

    fn log(&self, ticks: usize) {
        let insns = |dt: u32| u64::from(dt) * 1_000_000_000 / SYSTICK_HZ;
        let mean = self.total * 1_000_000_000 / SYSTICK_HZ / ticks.max(1) as u64;
        defmt::info!(
            "App::tick_with_pump: {=usize} ticks, {=u64} instructions per tick (mean, SysTick under -icount shift=0, ±6), {=u64} (max, at tick {=usize})",
            ticks,
            mean,
            insns(self.worst),
            self.worst_k
        );
        let top = &self.top;
        defmt::info!(
            "costliest ticks (instructions, tick): {=u64} {=usize}, {=u64} {=usize}, {=u64} {=usize}, {=u64} {=usize}, {=u64} {=usize}; {=u32} ticks over {=u64}",
            insns(top[0].0),
            top[0].1,
            insns(top[1].0),
            top[1].1,
            insns(top[2].0),
            top[2].1,
            insns(top[3].0),
            top[3].1,
            insns(top[4].0),
            top[4].1,
            self.over_budget,
            TICK_BUDGET_INSNS
        );
    }
}

/// The replay's checks, one line each.
fn log_verdict(v: &run::Verdict) {
    defmt::info!(
        "wy2 {=f64} (true {=f64}, tolerance {=f64}): {=bool}",
        v.wy2_est,
        v.wy2_true,
        v.wy2_tol,
        v.converged()
    );
    defmt::info!(
        "retune: {=u32} done, pump at the end {=f64} Hz (new sense resonance {=f64} Hz, tolerance {=f64} Hz): {=bool}",
        v.retunes,
        v.pump_end_hz,
        v.resonance_end_hz,
        v.pump_tol_hz,
        v.retuned()
    );
    defmt::info!(
        "DDS against the record's next pump: max {=f64} Hz (after the dither: {=f64} Hz), bound {=f64} Hz: {=bool}",
        v.dds_vs_record_max_hz,
        v.dds_vs_record_steady_max_hz,
        0.5 * run::pump_step_hz() + run::DDS_F32_MARGIN_HZ,
        v.dds_tracks_record()
    );
    defmt::info!(
        "bad ticks {=u32}, rate {=f64} dps, output digest {=u64:016x}",
        v.bad_ticks,
        v.rate_dps,
        v.digest
    );
}

#[exception]
unsafe fn HardFault(_ef: &cortex_m_rt::ExceptionFrame) -> ! {
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    exit(false)
}
