//! The store on a simulated NOR flash that loses power mid-operation.

use super::*;
use embedded_storage::nor_flash::{ErrorType, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use paragyro_core::Config;
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
        assert_eq!(warm_start(&mut s, &mut est), Start::Warm, "cut {cut}");
        // and the next save after the reboot works
        assert!(s.save(&snapshot(4)).is_ok());
        assert_eq!(s.load().unwrap().map(|r| r.seq), Some(r.seq + 1));
    }
    assert_eq!(torn_seen, total, "every cut before the end tore the save");
}

#[test]
fn first_save_torn_leaves_an_empty_store_and_a_cold_start() {
    let mut flash = SimFlash::new(2 * ERASE);
    flash.budget = Some(ERASE + 10);
    let mut s = store(flash);
    assert!(s.save(&snapshot(1)).is_err());
    let mut flash = s.release();
    flash.power_on();
    let mut s = store(flash);
    assert_eq!(s.load().unwrap(), None);
    let mut est = Config::table2().build::<f32>().unwrap();
    let design = est.theta();
    assert_eq!(
        warm_start(&mut s, &mut est),
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
        warm_start(&mut s, &mut est),
        Start::Cold(SnapshotError::Missing),
        "a record failing its CRC is no record"
    );
    let mut flash = s.release();
    flash.dead = true; // the flash does not answer
    let mut s = store(flash);
    assert_eq!(
        warm_start(&mut s, &mut est),
        Start::Cold(SnapshotError::Unreadable)
    );
    // a valid record of another configuration: refused by the core
    let mut s = store(SimFlash::new(2 * ERASE));
    let mut other = snapshot(1);
    other.config_crc ^= 1;
    s.save(&other).unwrap();
    assert_eq!(
        warm_start(&mut s, &mut est),
        Start::Cold(SnapshotError::Config)
    );
}
