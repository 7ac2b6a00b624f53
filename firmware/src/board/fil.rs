//! The `fil` board: QEMU's netduinoplus2 in the loop with the host process that plays the
//! chips (`paragyro-fil`, host-sim/fil; `cargo fw-loop`).
//!
//! The board is the real board's loop with the SPI buses replaced by the shims of
//! [`paragyro_firmware::fil`]: the chips are initialised by their drivers, the [`App`] is
//! built in place from the host's configuration, the pump is started, and then every tick
//! the board waits for DRDY (here: the host's message; a missing DRDY is counted and the
//! tick runs anyway, as on the stm32f405 board), runs the unchanged [`App::tick`], and
//! hands every byte it wrote to the AD9959 (and the IO_UPDATE pulses) back to the host.
//! One exchange per tick over two named pipes opened through semihosting
//! (TOOLCHAIN.md §3.1): `fil_to_fw` (read) then `fil_from_fw` (write), relative to QEMU's
//! working directory.
//!
//! The tick is bracketed by `fil::tick_begin`/`fil::tick_end` for the exact instruction
//! counter (firmware/tools/tickcount.c), and SysTick (±6 instructions under
//! `-icount shift=0`) times it too, for the host's log.
//!
//! [`App`]: paragyro_firmware::app::App
//! [`App::tick`]: paragyro_firmware::app::App::tick

use super::stack::{paint_stack, stack_high_water};
use cortex_m::peripheral::{SYST, syst::SystClkSource};
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, syscall};
use defmt_semihosting as _;
use embedded_hal::delay::DelayNs;
use paragyro_firmware::app::{App, Chips, PumpAmplitude, PumpGuard};
use paragyro_firmware::drivers::ad9959::{Ad9959, DEFAULT_SYSCLK_HZ};
use paragyro_firmware::drivers::ads131m08::{self, Ads131m08};
use paragyro_firmware::drivers::adxl355::{Adxl355, HighPass, Odr, Range};
use paragyro_firmware::fil::{
    self, FilAccel, FilAdc, FilBus, FilDds, FilIo, FromFw, INIT_BYTES, Init, TICK_END, TICK_SETUP,
    TO_FW_BYTES, ToFw, flag,
};
use paragyro_firmware::run::calibration;

/// SysTick runs at the core clock (168 MHz); under `-icount shift=0` one instruction is
/// one ns.
const SYSTICK_HZ: u64 = 168_000_000;

struct NoWait;

impl DelayNs for NoWait {
    fn delay_ns(&mut self, _ns: u32) {}
}

/// A semihosting file handle.
struct Fd(usize);

fn open(path: &[u8], mode: usize) -> Option<Fd> {
    // SYS_OPEN: NUL-terminated path, length without the NUL
    let len = path.len().checked_sub(1)?;
    // SAFETY: the path is a valid NUL-terminated buffer for the duration of the call.
    let fd = unsafe { syscall!(OPEN, path.as_ptr(), mode, len) } as isize;
    (fd >= 0).then_some(Fd(fd as usize))
}

fn read_exact(fd: &Fd, buf: &mut [u8]) -> bool {
    let mut done = 0usize;
    while done < buf.len() {
        let rest = &mut buf[done..];
        // SAFETY: the buffer is valid and writable for `rest.len()` bytes.
        let left = unsafe { syscall!(READ, fd.0, rest.as_mut_ptr(), rest.len()) };
        if left >= rest.len() {
            return false; // end of file or error: the host went away
        }
        done += rest.len() - left;
    }
    true
}

fn write_all(fd: &Fd, buf: &[u8]) -> bool {
    let mut done = 0usize;
    while done < buf.len() {
        let rest = &buf[done..];
        // SAFETY: the buffer is valid for `rest.len()` bytes.
        let left = unsafe { syscall!(WRITE, fd.0, rest.as_ptr(), rest.len()) };
        if left >= rest.len() {
            return false;
        }
        done += rest.len() - left;
    }
    true
}

fn range_of(bits: u32) -> Option<Range> {
    match bits {
        1 => Some(Range::G2),
        2 => Some(Range::G4),
        3 => Some(Range::G8),
        _ => None,
    }
}

/// Stack painting (as the qemu board): the free RAM between the statics and the stack
/// pointer is filled with this word at boot; the lowest word that no longer holds it gives
/// the stack's high-water mark, reported in the end answer.
#[entry]
fn main() -> ! {
    paint_stack();
    let ok = match cortex_m::Peripherals::take() {
        Some(mut cp) => session(&mut cp.SYST),
        None => false,
    };
    defmt::info!("{}", if ok { "fil: session done" } else { "fil: FAIL" });
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

type FilChips<'a> = Chips<FilAdc<'a>, FilAdc<'a>, FilAccel<'a>, FilDds<'a>>;
type FilApp<'a> = App<FilAdc<'a>, FilAdc<'a>, FilAccel<'a>, FilDds<'a>>;

#[inline(never)]
fn chips<'a>(bus: &'a FilBus, init: &Init) -> Option<FilChips<'a>> {
    let mut adc_x = Ads131m08::new(FilAdc::new(bus, 0));
    let mut adc_y = Ads131m08::new(FilAdc::new(bus, 1));
    adc_x.init(&mut NoWait, &ads131m08::Config::PARAGYRO).ok()?;
    adc_y.init(&mut NoWait, &ads131m08::Config::PARAGYRO).ok()?;
    let mut accel = Adxl355::new(FilAccel::new(bus));
    accel
        .init(range_of(init.accel_range_bits)?, Odr::Hz500, HighPass::Off)
        .ok()?;
    let mut dds = Ad9959::new(FilDds::new(bus), DEFAULT_SYSCLK_HZ);
    dds.init().ok()?;
    Some(Chips {
        adc_x,
        adc_y,
        accel,
        dds,
    })
}

#[inline(never)]
fn configure(app: &mut FilApp<'_>, init: &Init, io: &mut FilIo<'_>) -> bool {
    let cfg = init.config();
    let guard = PumpGuard::around(cfg.pump_centre_hz, init.guard_half_width_hz);
    let [base_scale, full_scale] = init.amplitude;
    if let Err(e) = app.configure(
        &cfg,
        calibration(init.um_per_volt[0]),
        calibration(init.um_per_volt[1]),
        guard,
    ) {
        defmt::error!("configuration rejected: {}", defmt::Debug2Format(&e));
        return false;
    }
    if app
        .set_pump_amplitude(PumpAmplitude {
            base_scale,
            full_scale,
        })
        .is_err()
    {
        defmt::error!("fil: amplitude mapping rejected");
        return false;
    }
    app.set_accel_stuck_limit(fil::ACCEL_STUCK_READS);
    app.set_half_steps(init.flags & fil::init_flag::HALF_STEPS != 0);
    if let Err(e) = app.start(io) {
        defmt::error!("fil: starting the pump failed: {}", defmt::Debug2Format(&e));
        return false;
    }
    true
}

fn report(app: &FilApp<'_>, drdy_missing: u32, out: &mut FromFw) {
    let f = app.counters();
    let c = app.estimator().counters();
    out.counters = [
        f.adc_spi_errors,
        f.adc_crc_errors,
        f.adc_not_ready,
        f.adc_saturated,
        f.accel_errors,
        f.accel_saturated,
        f.dds_errors,
        f.guard_clamps,
        drdy_missing,
        c.retunes,
        c.bad_samples,
        f.accel_stuck,
    ];
    out.wy2 = app.estimator().wy2();
    // the fast rate channel (the product's rate output; core::rate)
    let rate = app.estimator().rate_output();
    out.rate_dps = rate.rate_dps;
    out.rate_valid = rate.valid;
    out.pump_hz = app.pump_hz();
}

fn session(syst: &mut SYST) -> bool {
    let (Some(fin), Some(fout)) = (open(b"fil_to_fw\0", 0), open(b"fil_from_fw\0", 4)) else {
        defmt::error!("fil: cannot open the pipes fil_to_fw / fil_from_fw");
        return false;
    };
    let mut ib = [0u8; INIT_BYTES];
    let init = match read_exact(&fin, &mut ib)
        .then(|| Init::decode(&ib))
        .flatten()
    {
        Some(i) => i,
        None => {
            defmt::error!("fil: no set-up message");
            return false;
        }
    };
    let bus = FilBus::new();
    let mut io = FilIo::new(&bus);
    let Some(chips) = chips(&bus, &init) else {
        defmt::error!("fil: chip initialisation failed");
        return false;
    };
    // built in place, the estimator designed into it (as the other boards)
    let mut app = App::unconfigured(chips);
    bus.set_live(true);
    if !configure(&mut app, &init, &mut io) {
        return false;
    }
    let mut out = FromFw::EMPTY;
    out.tick = TICK_SETUP;
    report(&app, 0, &mut out);
    let mut log_ok = bus.take_log(&mut out);
    if !write_all(&fout, &out.encode()) {
        defmt::error!("fil: writing the set-up answer failed");
        return false;
    }
    defmt::info!("fil: set up, running the host's ticks");

    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(0x00FF_FFFF);
    syst.clear_current();
    syst.enable_counter();
    let insns = |dt: u32| (u64::from(dt & 0x00FF_FFFF) * 1_000_000_000 / SYSTICK_HZ) as u32;
    let mut drdy_missing = 0u32;
    let mut mb = [0u8; TO_FW_BYTES];
    loop {
        if !read_exact(&fin, &mut mb) {
            defmt::error!("fil: the host closed the pipe");
            return false;
        }
        let m = ToFw::decode(&mb);
        let mut out = FromFw::EMPTY;
        if m.flags & flag::END != 0 {
            out.tick = TICK_END;
            report(&app, drdy_missing, &mut out);
            out.stack_peak = stack_high_water() as u32;
            let ok = write_all(&fout, &out.encode());
            defmt::info!("fil: firmware counters {}", app.counters());
            defmt::info!("fil: core counters {}", app.estimator().counters());
            return ok && log_ok;
        }
        for (i, (kind, value)) in m.controls.iter().enumerate() {
            if i < usize::from(m.n_controls) {
                fil::apply_control(app.estimator_mut(), *kind, *value);
            }
        }
        if m.flags & flag::NO_DRDY != 0 {
            // the real board waits 4 ms for DRDY, counts it and runs the tick anyway
            drdy_missing = drdy_missing.saturating_add(1);
        }
        bus.load(&m);
        let pulses = io.pulses;
        let t0 = SYST::get_current();
        fil::tick_begin();
        let r = app.tick(&mut io);
        fil::tick_end();
        let t1 = SYST::get_current();
        out.tick = m.tick;
        out.faults = r.faults;
        out.sample_ok = r.sample_ok;
        out.inputs_valid = r.out.health.inputs_valid;
        out.updated = r.out.updated;
        out.events = r.out.events;
        out.health = r.out.health.bits();
        out.pump_hz_next = r.out.pump_hz_next;
        out.pump_scale_next = r.out.pump_scale_next;
        out.tick_insns = insns(t0.wrapping_sub(t1));
        out.pulse_at_insns = if io.pulses != pulses {
            out.tick_insns
        } else {
            0
        };
        report(&app, drdy_missing, &mut out);
        log_ok &= bus.take_log(&mut out);
        if !write_all(&fout, &out.encode()) {
            return false;
        }
    }
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
