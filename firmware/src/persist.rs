//! The warm-start record in flash, written so that a power loss never loses the last
//! good one.
//!
//! Two slots (A, B), each a whole number of erase sectors of a [`NorFlash`]. A record
//! is `magic | sequence number | the core's snapshot ([`SNAPSHOT_LEN`] bytes) | CRC-32`
//! ([`RECORD_LEN`] bytes); the CRC covers everything before it. A save goes to the slot
//! that does **not** hold the newest valid record: erase it, write the new record with
//! the next sequence number. Whatever point the power fails at (during the erase or the
//! write), the slot being written fails its CRC (or its magic) at the next boot and the
//! other slot, untouched, still holds the previous good record; a load takes the valid
//! record with the newest sequence number (compared modulo 2³²). Tested with a simulated
//! flash that loses power after every possible number of programmed bytes
//! (`persist/tests.rs`).
//!
//! [`warm_start`] is the boot hook: the board calls it on the built estimator before
//! `App::start` (`app.estimator_mut()`), and keeps the [`Start`] it returns (warm, or
//! cold with the reason: the flag). When to save is the board's decision: an erase of an
//! STM32F405 sector stalls the flash (and the code running from it) for up to seconds,
//! so a save belongs outside the 500 Hz loop (a commanded shutdown, a maintenance
//! window); [`should_save`] says whether the estimate is worth saving.
//!
//! Why not the `sequential-storage` crate the issue suggests: its API is async only
//! (`embedded-storage-async`), which would need an executor or a `block_on` on the boot
//! path; this store needs two slots and a CRC, about 150 lines.

use embedded_storage::nor_flash::NorFlash;
use paragyro_core::Estimator;
use paragyro_core::persist::{SNAPSHOT_LEN, Snapshot, SnapshotError, Start, crc32};

/// Magic at the start of a slot's record.
pub const RECORD_MAGIC: [u8; 4] = *b"PGS1";
/// Bytes of a record: magic (4), sequence number (4), snapshot, CRC-32 (4).
pub const RECORD_LEN: usize = 4 + 4 + SNAPSHOT_LEN + 4;

/// Why the store could not be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The slots overlap, are not aligned to erase sectors, are too small for a record,
    /// or the record is not a multiple of the write size.
    Layout,
    /// The flash reported an error (its kind is the driver's business).
    Flash,
}

/// A valid record read from a slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// Sequence number (each save the newest + 1, modulo 2³²).
    pub seq: u32,
    /// The snapshot's bytes ([`Snapshot::encode`]).
    pub snapshot: [u8; SNAPSHOT_LEN],
}

/// The two-slot store on a flash.
pub struct Store<F> {
    flash: F,
    /// Offsets of slots A and B.
    slots: [u32; 2],
    /// Bytes per slot (a multiple of the erase size).
    slot_len: u32,
}

/// `a` is newer than `b` (sequence numbers modulo 2³²).
fn newer(a: u32, b: u32) -> bool {
    a != b && a.wrapping_sub(b) < 1 << 31
}

impl<F: NorFlash> Store<F> {
    /// A store with slots at `slot_a` and `slot_b`, `slot_len` bytes each.
    pub fn new(flash: F, slot_a: u32, slot_b: u32, slot_len: u32) -> Result<Self, StoreError> {
        let erase = F::ERASE_SIZE as u32;
        let aligned = |v: u32| erase != 0 && v.checked_rem(erase) == Some(0);
        let end = |o: u32| o.checked_add(slot_len);
        let fits = match (end(slot_a), end(slot_b)) {
            (Some(ea), Some(eb)) => {
                (ea as usize) <= flash.capacity()
                    && (eb as usize) <= flash.capacity()
                    && (ea <= slot_b || eb <= slot_a)
            }
            _ => false,
        };
        let write_ok = F::WRITE_SIZE != 0 && RECORD_LEN.checked_rem(F::WRITE_SIZE) == Some(0);
        if !(fits
            && aligned(slot_a)
            && aligned(slot_b)
            && aligned(slot_len)
            && slot_len as usize >= RECORD_LEN
            && write_ok)
        {
            return Err(StoreError::Layout);
        }
        Ok(Store {
            flash,
            slots: [slot_a, slot_b],
            slot_len,
        })
    }

    /// The flash back.
    pub fn release(self) -> F {
        self.flash
    }

    /// The valid record of slot `i`, if any.
    fn read_slot(&mut self, at: u32) -> Result<Option<Record>, StoreError> {
        let mut buf = [0u8; RECORD_LEN];
        self.flash
            .read(at, &mut buf)
            .map_err(|_| StoreError::Flash)?;
        let (head, rest) = buf.split_at(8);
        let (body, crc) = rest.split_at(SNAPSHOT_LEN);
        let magic_ok = head.get(..4) == Some(&RECORD_MAGIC[..]);
        let seq = head
            .get(4..8)
            .and_then(|b| b.try_into().ok())
            .map(u32::from_le_bytes);
        let crc_stored = crc.try_into().ok().map(u32::from_le_bytes);
        let crc_now = buf
            .get(..RECORD_LEN.saturating_sub(4))
            .map(crc32)
            .unwrap_or(0);
        match (magic_ok, seq, crc_stored, body.try_into()) {
            (true, Some(seq), Some(c), Ok(snapshot)) if c == crc_now => {
                Ok(Some(Record { seq, snapshot }))
            }
            _ => Ok(None),
        }
    }

    /// Both slots' valid records.
    fn read_both(&mut self) -> Result<[Option<Record>; 2], StoreError> {
        let [a, b] = self.slots;
        Ok([self.read_slot(a)?, self.read_slot(b)?])
    }

    /// The newest valid record (`None`: both slots empty or torn).
    pub fn load(&mut self) -> Result<Option<Record>, StoreError> {
        Ok(match self.read_both()? {
            [Some(a), Some(b)] => Some(if newer(b.seq, a.seq) { b } else { a }),
            [a, b] => a.or(b),
        })
    }

    /// Saves `snap` into the slot that does not hold the newest record (erase, then
    /// write); returns the record's sequence number. A power loss at any point leaves
    /// the previous newest record readable.
    pub fn save(&mut self, snap: &Snapshot) -> Result<u32, StoreError> {
        let [a, b] = self.read_both()?;
        let (target, seq) = match (a, b) {
            (Some(a), Some(b)) if newer(b.seq, a.seq) => (0, b.seq.wrapping_add(1)),
            (Some(a), _) => (1, a.seq.wrapping_add(1)),
            (None, Some(b)) => (0, b.seq.wrapping_add(1)),
            (None, None) => (0, 1),
        };
        let [slot_a, slot_b] = self.slots;
        let at = if target == 0 { slot_a } else { slot_b };
        let mut rec = [0xFFu8; RECORD_LEN];
        let body = snap.encode();
        {
            let (head, rest) = rec.split_at_mut(8);
            let (magic, seq_b) = head.split_at_mut(4);
            magic.copy_from_slice(&RECORD_MAGIC);
            seq_b.copy_from_slice(&seq.to_le_bytes());
            let (snap_b, _) = rest.split_at_mut(SNAPSHOT_LEN);
            snap_b.copy_from_slice(&body);
        }
        let crc = rec
            .get(..RECORD_LEN.saturating_sub(4))
            .map(crc32)
            .unwrap_or(0);
        if let Some(tail) = rec.get_mut(RECORD_LEN.saturating_sub(4)..) {
            tail.copy_from_slice(&crc.to_le_bytes());
        }
        let flash_err = |_: F::Error| StoreError::Flash;
        self.flash
            .erase(at, at.saturating_add(self.slot_len))
            .map_err(flash_err)?;
        self.flash.write(at, &rec).map_err(flash_err)?;
        Ok(seq)
    }
}

/// The boot hook: the newest record of `store` into `est` (a freshly built estimator,
/// before its first step). Warm, or cold with the reason: no record (`Missing`), a
/// flash error (`Unreadable`), or what [`Estimator::boot_from`] refused.
pub fn warm_start<F: NorFlash>(store: &mut Store<F>, est: &mut Estimator<f32>) -> Start {
    match store.load() {
        Ok(Some(r)) => est.boot_from(Some(&r.snapshot)),
        Ok(None) => Start::Cold(SnapshotError::Missing),
        Err(_) => Start::Cold(SnapshotError::Unreadable),
    }
}

/// The estimate is worth saving: settled and actionable (a snapshot that was not
/// settled is refused at boot anyway).
pub fn should_save(est: &Estimator<f32>) -> bool {
    let h = est.health();
    h.settled && h.actionable()
}

#[cfg(test)]
mod tests;
