//! The store on a simulated NOR flash that loses power mid-operation.

use super::*;
use embedded_storage::nor_flash::{ErrorType, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use paragyro_core::Config;
use paragyro_core::health::Health;
use paragyro_core::persist::config_crc;
use paragyro_core::physics::theta_from_physical;

const ERASE: usize = 256;

/// A NOR flash in RAM: erase sets bytes to 0xFF, a write can only clear bits
/// (`old & new`). `budget` bytes may still be erased or programmed before the power
/// fails: the operation in progress stops there (its first bytes done, the rest not)
/// and every later operation fails until [`SimFlash::power_on`].
#[derive(Clone)]
struct SimFlash {
    mem: Vec<u8>,
    budget: Option<usize>,
    dead: bool,
    ops: usize,
    /// Erase calls, and the longest single write (bytes).
    erases: usize,
    max_write: usize,
}

#[derive(Debug)]
struct PowerLoss;
impl NorFlashError for PowerLoss {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::Other
    }
}

impl SimFlash {
    fn new(len: usize) -> Self {
        SimFlash {
            mem: vec![0xFF; len],
            budget: None,
            dead: false,
            ops: 0,
            erases: 0,
            max_write: 0,
        }
    }
    fn power_on(&mut self) {
        self.dead = false;
        self.budget = None;
    }
    /// Spends one byte of the budget; false: the power is gone.
    fn spend(&mut self) -> bool {
        if self.dead {
            return false;
        }
        self.ops += 1;
        match &mut self.budget {
            Some(0) => {
                self.dead = true;
                false
            }
            Some(n) => {
                *n -= 1;
                true
            }
            None => true,
        }
    }
}

impl ErrorType for SimFlash {
    type Error = PowerLoss;
}

impl ReadNorFlash for SimFlash {
    const READ_SIZE: usize = 1;
    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), PowerLoss> {
        if self.dead {
            return Err(PowerLoss);
        }
        let o = offset as usize;
        bytes.copy_from_slice(&self.mem[o..o + bytes.len()]);
        Ok(())
    }
    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl NorFlash for SimFlash {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = ERASE;
    fn erase(&mut self, from: u32, to: u32) -> Result<(), PowerLoss> {
        assert!((from as usize).is_multiple_of(ERASE) && (to as usize).is_multiple_of(ERASE));
        self.erases += 1;
        for i in from as usize..to as usize {
            if !self.spend() {
                return Err(PowerLoss);
            }
            self.mem[i] = 0xFF;
        }
        Ok(())
    }
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), PowerLoss> {
        assert!((offset as usize).is_multiple_of(4) && bytes.len().is_multiple_of(4));
        self.max_write = self.max_write.max(bytes.len());
        for (i, b) in bytes.iter().enumerate() {
            if !self.spend() {
                // the byte being programmed when the power went: half its bits
                self.mem[offset as usize + i] &= b | 0x0F;
                return Err(PowerLoss);
            }
            self.mem[offset as usize + i] &= b;
        }
        Ok(())
    }
}

fn snapshot(i: u32) -> Snapshot {
    let cfg = Config::table2();
    let (t1, t2) = theta_from_physical(&cfg.nominal);
    let mut t1 = t1;
    t1[0] *= 1.0 + i as f64 * 1e-3;
    Snapshot {
        config_crc: config_crc(&cfg),
        health_bits: 0x3F,
        theta1: t1,
        theta2: t2,
        pump_centre_hz: cfg.pump_centre_hz + i as f64,
        traces: [1e-6, 1e-6],
        temp_c: 25.0,
        dtheta_dt: [0.0; 2],
        dtheta_dt_var: [1e-16; 2],
        zero: [cfg.nominal.mu_xy, 12_000.0],
    }
}

fn store(flash: SimFlash) -> Store<SimFlash> {
    Store::new(flash, 0, ERASE as u32, ERASE as u32).unwrap()
}

#[test]
fn layout_is_checked() {
    let f = || SimFlash::new(4 * ERASE);
    assert!(Store::new(f(), 0, ERASE as u32, ERASE as u32).is_ok());
    assert_eq!(
        Store::new(f(), 0, 0, ERASE as u32).err(),
        Some(StoreError::Layout)
    );
    assert_eq!(
        Store::new(f(), 0, 100, ERASE as u32).err(),
        Some(StoreError::Layout)
    );
    assert_eq!(
        Store::new(f(), 0, ERASE as u32, 128).err(),
        Some(StoreError::Layout)
    );
    assert_eq!(
        Store::new(f(), 0, 3 * ERASE as u32, 2 * ERASE as u32).err(),
        Some(StoreError::Layout)
    );
    assert!(RECORD_LEN.is_multiple_of(4));
}

#[test]
fn save_alternates_slots_and_load_takes_the_newest() {
    let mut s = store(SimFlash::new(2 * ERASE));
    assert_eq!(s.load().unwrap(), None);
    for i in 1..=5u32 {
        assert_eq!(s.save(&snapshot(i)).unwrap(), i);
        let r = s.load().unwrap().unwrap();
        assert_eq!(r.seq, i);
        assert_eq!(Snapshot::decode(&r.snapshot), Ok(snapshot(i)));
    }
    // the sequence number compares across its wrap
    assert!(newer(0, u32::MAX) && newer(3, u32::MAX - 2) && !newer(u32::MAX, 0));
}

#[test]
fn power_loss_at_every_byte_of_a_save_never_loses_the_previous_record() {
    // two saves done (both slots hold records), then a third that loses power
    let mut good = store(SimFlash::new(2 * ERASE));
    good.save(&snapshot(1)).unwrap();
    good.save(&snapshot(2)).unwrap();
    let base = good.release();
    let mut probe = base.clone();
    probe.ops = 0;
    let mut s = store(probe);
    s.save(&snapshot(3)).unwrap();
    let total = s.release().ops;
    assert_eq!(total, ERASE + RECORD_LEN, "one erase and one record");
    let mut torn_seen = 0;
    for cut in 0..=total {
        let mut flash = base.clone();
        flash.budget = Some(cut);
        let mut s = store(flash);
        let saved = s.save(&snapshot(3));
        let mut flash = s.release();
        flash.power_on();
        let mut s = store(flash);
        let r = s.load().unwrap().expect("no record after a power loss");
        let got = Snapshot::decode(&r.snapshot).unwrap();
        if saved.is_ok() {
            assert_eq!((r.seq, got), (3, snapshot(3)), "cut {cut}");
        } else {
            torn_seen += 1;
            assert_eq!(
                (r.seq, got),
                (2, snapshot(2)),
                "cut {cut}: previous record lost"
            );
        }
        // the boot hook starts warm from whichever record survived
        let mut est = Config::table2().build::<f32>().unwrap();
        assert_eq!(warm_start(&mut s, &mut est, None), Start::Warm, "cut {cut}");
        // and the next save after the reboot works
        assert!(s.save(&snapshot(4)).is_ok());
        assert_eq!(s.load().unwrap().map(|r| r.seq), Some(r.seq + 1));
    }
    assert_eq!(torn_seen, total, "every cut before the end tore the save");
}

#[test]
fn first_save_torn_leaves_an_empty_store_and_a_cold_start() {
    let mut flash = SimFlash::new(2 * ERASE);
    // a blank store: the first save does not erase, the power goes 10 bytes into it
    flash.budget = Some(10);
    let mut s = store(flash);
    assert!(s.save(&snapshot(1)).is_err());
    let mut flash = s.release();
    flash.power_on();
    let mut s = store(flash);
    assert_eq!(s.load().unwrap(), None);
    let mut est = Config::table2().build::<f32>().unwrap();
    let design = est.theta();
    assert_eq!(
        warm_start(&mut s, &mut est, None),
        Start::Cold(SnapshotError::Missing)
    );
    assert_eq!(est.theta(), design);
}

#[test]
fn corrupt_and_unreadable_records_start_cold_with_the_reason() {
    let mut s = store(SimFlash::new(2 * ERASE));
    s.save(&snapshot(1)).unwrap();
    let mut flash = s.release();
    flash.mem[20] ^= 0x01; // a bit flips in the only record
    let mut s = store(flash);
    let mut est = Config::table2().build::<f32>().unwrap();
    assert_eq!(
        warm_start(&mut s, &mut est, None),
        Start::Cold(SnapshotError::Missing),
        "a record failing its CRC is no record"
    );
    let mut flash = s.release();
    flash.dead = true; // the flash does not answer
    let mut s = store(flash);
    assert_eq!(
        warm_start(&mut s, &mut est, None),
        Start::Cold(SnapshotError::Unreadable)
    );
    // a valid record of another configuration: refused by the core
    let mut s = store(SimFlash::new(2 * ERASE));
    let mut other = snapshot(1);
    other.config_crc ^= 1;
    s.save(&other).unwrap();
    assert_eq!(
        warm_start(&mut s, &mut est, None),
        Start::Cold(SnapshotError::Config)
    );
}

/// Slots of three erase sectors: three records each.
fn big_store(flash: SimFlash) -> Store<SimFlash> {
    Store::new(flash, 0, 3 * ERASE as u32, 3 * ERASE as u32).unwrap()
}

/// A save through the loop's path: begin, then `chunk` bytes per call.
fn chunked_save(s: &mut Store<SimFlash>, snap: &Snapshot, chunk: usize) -> Result<u32, StoreError> {
    let seq = s.begin_save(snap)?;
    let mut calls = 0;
    loop {
        calls += 1;
        assert!(calls <= RECORD_LEN, "a save that never ends");
        if let Some(done) = s.continue_save(chunk)? {
            assert_eq!(done, seq);
            return Ok(seq);
        }
    }
}

#[test]
fn the_loop_appends_then_switches_to_the_erased_slot_and_never_erases() {
    let mut s = big_store(SimFlash::new(6 * ERASE));
    assert_eq!(s.records_per_slot(), 3);
    assert_eq!(s.prepare(), Ok(false), "blank spare: no erase");
    for i in 1..=6u32 {
        assert_eq!(chunked_save(&mut s, &snapshot(i), 8), Ok(i));
        assert!(!s.busy());
    }
    // both slots used up: the loop's path refuses rather than erase
    assert_eq!(s.begin_save(&snapshot(7)), Err(StoreError::NeedsErase));
    let mut flash = s.release();
    assert_eq!(flash.erases, 0, "an erase in the loop");
    assert_eq!(flash.max_write, 8, "more than a chunk in one write");
    // records 4..6 in slot B, in order; 1..3 in slot A
    for (i, seq) in [1u32, 2, 3, 4, 5, 6].iter().enumerate() {
        let at = i * RECORD_LEN
            + if i >= 3 {
                3 * ERASE - 3 * RECORD_LEN
            } else {
                0
            };
        assert_eq!(flash.mem[at..at + 4], RECORD_MAGIC, "record {seq}");
        assert_eq!(flash.mem[at + 4..at + 8], seq.to_le_bytes(), "record {seq}");
    }
    // the next boot erases slot A (the one without the newest record), once
    flash.erases = 0;
    let mut s = big_store(flash);
    assert_eq!(s.load().unwrap().map(|r| r.seq), Some(6));
    assert_eq!(s.prepare(), Ok(true));
    assert_eq!(s.prepare(), Ok(false), "erased already");
    assert_eq!(s.load().unwrap().map(|r| r.seq), Some(6), "newest kept");
    assert_eq!(chunked_save(&mut s, &snapshot(7), 8), Ok(7));
    assert_eq!(s.load().unwrap().map(|r| r.seq), Some(7));
    assert_eq!(s.release().erases, 1);
}

#[test]
fn power_loss_at_every_byte_of_a_chunked_save_keeps_the_previous_record() {
    let mut good = big_store(SimFlash::new(6 * ERASE));
    for i in 1..=2 {
        chunked_save(&mut good, &snapshot(i), 8).unwrap();
    }
    let base = good.release();
    for cut in 0..RECORD_LEN {
        let mut flash = base.clone();
        flash.budget = Some(cut);
        let mut s = big_store(flash);
        assert_eq!(
            chunked_save(&mut s, &snapshot(3), 8),
            Err(StoreError::Flash),
            "cut {cut}"
        );
        assert!(!s.busy(), "a failed save stays pending");
        let mut flash = s.release();
        flash.power_on();
        let mut s = big_store(flash);
        let r = s.load().unwrap().expect("previous record lost");
        assert_eq!(r.seq, 2, "cut {cut}");
        assert_eq!(Snapshot::decode(&r.snapshot), Ok(snapshot(2)));
        // the torn position is skipped: the next record goes after it, in slot B
        // (slot A: records 1, 2 and the torn one), and becomes the newest
        assert_eq!(s.prepare(), Ok(false));
        assert_eq!(chunked_save(&mut s, &snapshot(4), 8), Ok(3));
        let mut flash = s.release();
        let at = 3 * ERASE;
        assert_eq!(flash.mem[at..at + 4], RECORD_MAGIC, "cut {cut}");
        let mut s = big_store(flash.clone());
        let r = s.load().unwrap().unwrap();
        assert_eq!((r.seq, Snapshot::decode(&r.snapshot)), (3, Ok(snapshot(4))));
        flash.power_on();
    }
}

fn health(settled: bool) -> Health {
    Health {
        inputs_valid: true,
        excitation_ok: true,
        covariance_bounded: true,
        change_detected: false,
        drive_locked: true,
        settled,
        gated: false,
        retuning: false,
    }
}

#[test]
fn the_policy_saves_after_the_hold_then_once_more_then_after_retunes_and_on_refresh() {
    let p = SavePolicy {
        hold_ticks: 100,
        min_interval_ticks: 1000,
        refresh_ticks: 5000,
        chunk_bytes: 8,
    };
    let mut sv = Saver::new(p);
    assert!(!sv.due(0, &health(false), 0), "not settled");
    assert!(!sv.due(10, &health(true), 0));
    assert!(!sv.due(109, &health(true), 0), "settled 99 ticks");
    assert!(!sv.due(110, &health(false), 0), "a break restarts the hold");
    assert!(!sv.due(111, &health(true), 0));
    assert!(!sv.due(210, &health(true), 0));
    assert!(
        sv.due(211, &health(true), 0),
        "settled for the hold: first save"
    );
    let mut unsettled_gated = health(true);
    unsettled_gated.gated = true;
    assert!(!sv.due(211, &unsettled_gated, 0), "not actionable");
    // until the run has two records, one per minimum interval without a retune (the
    // first is taken before the rate's zero has learned)
    sv.settled_since = Some(0);
    sv.last_save = Some(211);
    sv.written = 1;
    assert!(!sv.due(1210, &health(true), 0));
    assert!(sv.due(1211, &health(true), 0), "the run's second record");
    sv.last_save = Some(300);
    sv.written = 2;
    sv.retunes_at_save = 0;
    assert!(!sv.due(1300, &health(true), 0), "nothing new");
    assert!(
        !sv.due(1000, &health(true), 1),
        "retune within the minimum interval"
    );
    assert!(sv.due(1300, &health(true), 1), "retune, interval elapsed");
    assert!(!sv.due(5299, &health(true), 0));
    assert!(sv.due(5300, &health(true), 0), "hourly refresh");
    // across the tick counter's wrap
    sv.last_save = Some(u32::MAX - 10);
    sv.settled_since = Some(u32::MAX - 500);
    assert!(!sv.due(100, &health(true), 1));
    assert!(sv.due(989, &health(true), 1));
    sv.full = true;
    assert!(
        !sv.due(u32::MAX - 20, &health(true), 7),
        "full: no more saves this run"
    );
}

#[test]
fn the_saver_on_the_replay_run_saves_once_settled_in_chunks_and_boots_warm_from_it() {
    use crate::drivers::ad9959::DEFAULT_SYSCLK_HZ;
    use crate::replay::DdsCapture;
    use crate::run::{apply_controls, replay_app};
    use crate::table::ReplayTable;
    use embedded_hal_mock::eh1::delay::NoopDelay;
    static TABLE: &[u8] = include_bytes!("../../replay/fw-drift-retune.bin");

    let table = ReplayTable::parse(TABLE).expect("table");
    let cap = DdsCapture::new(DEFAULT_SYSCLK_HZ);
    let mut io = cap.io_update();
    let mut app = replay_app(table, &cap, &mut io, &mut NoopDelay::new()).expect("setup");
    let mut s = big_store(SimFlash::new(6 * ERASE));
    // a cold boot from the empty store: the flag says why
    let b = boot(&mut s, app.estimator_mut(), None);
    assert_eq!(
        b,
        Boot {
            start: Start::Cold(SnapshotError::Missing),
            prepared: Ok(false)
        }
    );
    // the board's policy with the intervals shortened to fit the 20 s record
    let policy = SavePolicy {
        hold_ticks: 250,
        min_interval_ticks: 1000,
        refresh_ticks: 4000,
        chunk_bytes: 8,
    };
    let mut sv = Saver::new(policy);
    let mut events = Vec::new();
    let mut settled_at = None;
    for k in 0..table.len() {
        apply_controls(&table, k, &mut app);
        let (p, sc) = table.pump(k).unwrap();
        let _ = app.tick_with_pump(&mut io, p, sc);
        let h = app.estimator().health();
        if h.settled && h.actionable() {
            settled_at.get_or_insert(k as u32);
        }
        let ev = sv.poll(&mut s, k as u32, app.estimator());
        if ev != SaveEvent::Idle {
            events.push((k as u32, ev, app.estimator().counters().retunes));
        }
    }
    println!("settled at {settled_at:?}; events {events:?}");
    let settled_at = settled_at.expect("the replay run never settled");
    let (k0, first, _) = events[0];
    assert_eq!(first, SaveEvent::Started(1));
    assert!(
        k0 >= settled_at + policy.hold_ticks,
        "saved before the hold"
    );
    assert_eq!(
        events[1],
        (
            k0 + RECORD_LEN as u32 / 8,
            SaveEvent::Written(1),
            events[1].2
        ),
        "{RECORD_LEN} B in 8 B a tick"
    );
    assert!(
        events.iter().all(|e| !matches!(e.1, SaveEvent::Failed(_))),
        "a save failed"
    );
    let starts: Vec<u32> = events
        .iter()
        .filter(|e| matches!(e.1, SaveEvent::Started(_)))
        .map(|e| e.0)
        .collect();
    assert!(
        starts
            .windows(2)
            .all(|w| w[1] - w[0] >= policy.min_interval_ticks),
        "{starts:?}"
    );
    assert!(app.estimator().counters().retunes > 0, "the record retunes");
    assert_eq!(sv.written as usize, starts.len());
    let flash = s.release();
    assert_eq!(flash.erases, 0);
    assert_eq!(flash.max_write, 8);

    // the next boot: a fresh board over the same record, warm from the newest record
    let cap = DdsCapture::new(DEFAULT_SYSCLK_HZ);
    let mut io = cap.io_update();
    let mut app2 = replay_app(table, &cap, &mut io, &mut NoopDelay::new()).expect("setup");
    let mut s = big_store(flash);
    let newest = s.load().unwrap().unwrap();
    assert_eq!(newest.seq, sv.written);
    let b = boot(&mut s, app2.estimator_mut(), None);
    assert_eq!(b.start, Start::Warm);
    let snap = Snapshot::decode(&newest.snapshot).unwrap();
    let (t1, t2) = app2.estimator().theta();
    assert_eq!((t1, t2), (snap.theta1, snap.theta2));
}

#[test]
fn the_boot_moves_a_record_to_the_die_temperature_it_reads() {
    // a record taken at 25 °C with the sense frequency's learned −33 ppm/K (θ22 rises
    // 66 ppm of ω_y² per K), booted at 35 °C: the pump starts 330 ppm lower
    let rec = Snapshot {
        temp_c: 25.0,
        dtheta_dt: [0.0, 66e-6 * Config::table2().nominal.wy2],
        dtheta_dt_var: [1e-16, 1e-16],
        ..snapshot(1)
    };
    let mut s = store(SimFlash::new(2 * ERASE));
    assert!(s.save(&rec).is_ok());
    let mut est = Config::table2().build::<f32>().unwrap();
    assert_eq!(warm_start(&mut s, &mut est, Some(35.0)), Start::Warm);
    // the record's pump sits 1 Hz off 2·f_y(25 °C) (`snapshot(1)`): the boot puts it at
    // 2·f_y(35 °C)
    let f_y25 = 2.0 * Config::table2().f0_hz * Config::table2().nominal.wy2.sqrt();
    let dp = f_y25 - est.initial_pump_hz();
    assert!((dp - 330e-6 * f_y25).abs() < 0.01, "{dp} Hz");
    // no reading at boot: the record as taken
    let mut est = Config::table2().build::<f32>().unwrap();
    assert_eq!(warm_start(&mut s, &mut est, None), Start::Warm);
    assert!((est.initial_pump_hz() - rec.pump_centre_hz).abs() < 1e-6);
}
