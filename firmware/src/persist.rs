//! The warm-start record in flash, written so that a power loss never loses the last
//! good one, and so that the 500 Hz loop never waits for an erase.
//!
//! Two slots (A, B), each a whole number of erase sectors of a [`NorFlash`]. A record
//! is `magic | sequence number | the core's snapshot ([`SNAPSHOT_LEN`] bytes) | CRC-32`
//! ([`RECORD_LEN`] bytes); the CRC covers everything before it. Records are appended
//! one after the other in the slot holding the newest one (a 128 KiB slot holds 780);
//! when it is full the next record goes to the start of the other slot, which must be
//! blank. A save never overwrites the newest record: whatever point the power fails at
//! (during a write or an erase), the position being written fails its CRC (or its
//! magic) at the next boot and the newest record before it is still readable; a load
//! takes the valid record with the newest sequence number (compared modulo 2³²).
//! Tested with a simulated flash that loses power after every possible number of
//! programmed bytes (`persist/tests.rs`).
//!
//! **Erases happen at boot only** ([`Store::prepare`], from [`boot`]): the slot not
//! holding the newest record is erased if anything was written in it. An erase of an
//! STM32F405 128 KiB sector takes 1–4 s and stalls every flash read (the code runs from
//! flash), so inside the loop the [`Saver`] only programs, a few bytes per tick
//! ([`SavePolicy`]), and when both slots are used up it stops saving for the run
//! ([`StoreError::NeedsErase`], [`Saver::full`]) until the next boot erases one.
//! [`Store::save`] is the blocking version (erase if needed, then the whole record).
//!
//! [`warm_start`] is the boot hook: the board calls it (through [`boot`]) on the built
//! estimator before `App::start` (`app.estimator_mut()`), and keeps the [`Start`] it
//! returns (warm, or cold with the reason: the flag).
//!
//! Why not the `sequential-storage` crate the issue suggests: its API is async only
//! (`embedded-storage-async`), which would need an executor or a `block_on` on the boot
//! path, and it erases when a page fills, inside whatever call needs the room.

use embedded_storage::nor_flash::NorFlash;
use paragyro_core::Estimator;
use paragyro_core::health::Health;
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
    /// A save is already in progress.
    Busy,
    /// Both slots are used up and the saves of a run do not erase: the next boot's
    /// [`Store::prepare`] erases one.
    NeedsErase,
}

/// A valid record read from a slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Record {
    /// Sequence number (each save the newest + 1, modulo 2³²).
    pub seq: u32,
    /// The snapshot's bytes ([`Snapshot::encode`]).
    pub snapshot: [u8; SNAPSHOT_LEN],
}

/// Where a record sits: slot (0 = A, 1 = B), record index in the slot, sequence number.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Place {
    slot: usize,
    index: u32,
    seq: u32,
}

/// What a scan of both slots found (kept in RAM between saves: a save in the loop
/// must not re-read 256 KiB).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Scan {
    /// The newest valid record.
    newest: Option<Place>,
    /// Per slot: the index after its last programmed record position (`None`: full).
    next: [Option<u32>; 2],
    /// Per slot: no record position programmed (a new record can go at index 0).
    blank: [bool; 2],
}

impl Scan {
    /// Record position `index` of `slot` is programmed (in part or whole).
    fn used(&mut self, slot: usize, index: u32, per_slot: u32) {
        if let (Some(b), Some(nx)) = (self.blank.get_mut(slot), self.next.get_mut(slot)) {
            *b = false;
            *nx = index.checked_add(1).filter(|i| *i < per_slot);
        }
    }
}

/// A save in progress: the record, where it goes, how many bytes are written.
struct Pending {
    place: Place,
    rec: [u8; RECORD_LEN],
    done: usize,
}

/// The two-slot store on a flash: records appended one after the other in a slot, the
/// other slot erased ahead of time (see the module doc).
pub struct Store<F> {
    flash: F,
    /// Offsets of slots A and B.
    slots: [u32; 2],
    /// Bytes per slot (a multiple of the erase size).
    slot_len: u32,
    /// Records per slot.
    per_slot: u32,
    scan: Option<Scan>,
    pending: Option<Pending>,
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
            per_slot: slot_len.checked_div(RECORD_LEN as u32).unwrap_or(0),
            scan: None,
            pending: None,
        })
    }

    /// The flash back.
    pub fn release(self) -> F {
        self.flash
    }

    /// Records a slot holds.
    pub fn records_per_slot(&self) -> u32 {
        self.per_slot
    }

    /// Offset of record `index` of `slot`.
    fn offset(&self, slot: usize, index: u32) -> u32 {
        let base = if slot == 0 {
            self.slots[0]
        } else {
            self.slots[1]
        };
        base.saturating_add(index.saturating_mul(RECORD_LEN as u32))
    }

    /// The record position at `at`: its valid record if any, and whether it is blank
    /// (never programmed since the erase).
    fn read_at(&mut self, at: u32) -> Result<(Option<Record>, bool), StoreError> {
        let mut buf = [0u8; RECORD_LEN];
        self.flash
            .read(at, &mut buf)
            .map_err(|_| StoreError::Flash)?;
        let blank = buf.iter().all(|b| *b == 0xFF);
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
        let rec = match (magic_ok, seq, crc_stored, body.try_into()) {
            (true, Some(seq), Some(c), Ok(snapshot)) if c == crc_now => {
                Some(Record { seq, snapshot })
            }
            _ => None,
        };
        Ok((rec, blank))
    }

    /// Reads every record position of both slots.
    fn rescan(&mut self) -> Result<Scan, StoreError> {
        self.scan = None;
        let mut sc = Scan {
            newest: None,
            next: [Some(0); 2],
            blank: [true; 2],
        };
        for slot in 0..2 {
            for index in 0..self.per_slot {
                let (rec, blank) = self.read_at(self.offset(slot, index))?;
                if let Some(r) = rec
                    && sc.newest.is_none_or(|n| newer(r.seq, n.seq))
                {
                    sc.newest = Some(Place {
                        slot,
                        index,
                        seq: r.seq,
                    });
                }
                if !blank {
                    sc.used(slot, index, self.per_slot);
                }
            }
        }
        self.scan = Some(sc);
        Ok(sc)
    }

    /// The scan (read once, then kept up to date by the saves).
    fn state(&mut self) -> Result<Scan, StoreError> {
        match self.scan {
            Some(sc) => Ok(sc),
            None => self.rescan(),
        }
    }

    /// The slot holding the newest record (A when there is none).
    fn current(sc: &Scan) -> usize {
        sc.newest.map_or(0, |p| p.slot)
    }

    /// Where the next record goes, and whether that slot must be erased first.
    fn target(sc: &Scan) -> (usize, u32, bool) {
        let cur = Self::current(sc);
        let other = cur ^ 1;
        match sc.next.get(cur).copied().flatten() {
            Some(i) => (cur, i, false),
            None => (other, 0, !sc.blank.get(other).copied().unwrap_or(false)),
        }
    }

    /// The newest valid record (`None`: both slots empty or torn). Reads the flash.
    #[inline(never)]
    pub fn load(&mut self) -> Result<Option<Record>, StoreError> {
        let sc = self.rescan()?;
        match sc.newest {
            Some(p) => Ok(self.read_at(self.offset(p.slot, p.index))?.0),
            None => Ok(None),
        }
    }

    /// Erases `slot` (never the one holding the newest record).
    #[inline(never)]
    fn erase_slot(&mut self, slot: usize) -> Result<(), StoreError> {
        let at = self.offset(slot, 0);
        self.scan = None;
        self.flash
            .erase(at, at.saturating_add(self.slot_len))
            .map_err(|_| StoreError::Flash)?;
        self.rescan().map(|_| ())
    }

    /// The boot-time preparation: erases the slot not holding the newest record if
    /// anything was programmed in it, so that the saves of this run never erase (an
    /// erase stalls the flash). Returns whether it erased.
    #[inline(never)]
    pub fn prepare(&mut self) -> Result<bool, StoreError> {
        let sc = self.state()?;
        let other = Self::current(&sc) ^ 1;
        if sc.blank.get(other).copied().unwrap_or(false) {
            return Ok(false);
        }
        self.erase_slot(other).map(|_| true)
    }

    /// A save is in progress ([`Self::begin_save`] until [`Self::continue_save`]
    /// finishes it).
    pub fn busy(&self) -> bool {
        self.pending.is_some()
    }

    /// Starts a save of `snap` without erasing: the record goes after the newest one,
    /// or at the start of the other slot if that one is blank; `NeedsErase` if neither
    /// can take it. Returns the record's sequence number; nothing is written yet.
    #[inline(never)]
    pub fn begin_save(&mut self, snap: &Snapshot) -> Result<u32, StoreError> {
        if self.pending.is_some() {
            return Err(StoreError::Busy);
        }
        let sc = self.state()?;
        let (slot, index, needs_erase) = Self::target(&sc);
        if needs_erase {
            return Err(StoreError::NeedsErase);
        }
        let seq = sc.newest.map_or(1, |p| p.seq.wrapping_add(1));
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
        self.pending = Some(Pending {
            place: Place { slot, index, seq },
            rec,
            done: 0,
        });
        Ok(seq)
    }

    /// Programs at most `max_bytes` more of the save in progress (at least one write
    /// unit, in order, the CRC last); `Some(seq)` when the record is complete. The
    /// record position is used up either way (a torn record fails its CRC).
    #[inline(never)]
    pub fn continue_save(&mut self, max_bytes: usize) -> Result<Option<u32>, StoreError> {
        let Some(mut p) = self.pending.take() else {
            return Ok(None);
        };
        let w = F::WRITE_SIZE.max(1);
        let n = max_bytes
            .saturating_sub(max_bytes.checked_rem(w).unwrap_or(0))
            .max(w);
        let end = p.done.saturating_add(n).min(RECORD_LEN);
        let at = self
            .offset(p.place.slot, p.place.index)
            .saturating_add(p.done as u32);
        let chunk = p.rec.get(p.done..end).unwrap_or(&[]);
        let wrote = self.flash.write(at, chunk);
        if let Some(sc) = self.scan.as_mut() {
            sc.used(p.place.slot, p.place.index, self.per_slot);
        }
        if wrote.is_err() {
            return Err(StoreError::Flash);
        }
        p.done = end;
        if p.done < RECORD_LEN {
            self.pending = Some(p);
            return Ok(None);
        }
        if let Some(sc) = self.scan.as_mut() {
            sc.newest = Some(p.place);
        }
        Ok(Some(p.place.seq))
    }

    /// Saves `snap` at once, erasing the other slot first if it must (blocking: not
    /// for the 500 Hz loop, see [`Saver`]); returns the record's sequence number. A
    /// power loss at any point leaves the previous newest record readable.
    pub fn save(&mut self, snap: &Snapshot) -> Result<u32, StoreError> {
        if self.pending.is_some() {
            return Err(StoreError::Busy);
        }
        let sc = self.state()?;
        if let (slot, _, true) = Self::target(&sc) {
            self.erase_slot(slot)?;
        }
        self.begin_save(snap)?;
        match self.continue_save(RECORD_LEN)? {
            Some(seq) => Ok(seq),
            None => Err(StoreError::Flash),
        }
    }
}

/// The boot hook: the newest record of `store` into `est` (a freshly built estimator,
/// before its first step) at the die temperature `temp_c` (the accelerometer's reading
/// at boot; the record's learned coefficients move θ and the pump to it). Warm, or cold
/// with the reason: no record (`Missing`), a flash error (`Unreadable`), or what
/// [`Estimator::boot_from_at`] refused.
#[inline(never)]
pub fn warm_start<F: NorFlash>(
    store: &mut Store<F>,
    est: &mut Estimator<f32>,
    temp_c: Option<f32>,
) -> Start {
    match store.load() {
        Ok(Some(r)) => est.boot_from_at(Some(&r.snapshot), temp_c.map(f64::from)),
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

/// When the board saves (in ticks of the 500 Hz loop).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SavePolicy {
    /// The estimate must have been settled and actionable ([`should_save`]) this long,
    /// without a break, before a save.
    pub hold_ticks: u32,
    /// At least this long between two saves (also after a failed one).
    pub min_interval_ticks: u32,
    /// A save after this long even without a retune (θ follows temperature slowly).
    pub refresh_ticks: u32,
    /// Bytes programmed per tick while a save is in progress.
    pub chunk_bytes: usize,
}

impl SavePolicy {
    /// The stm32f405 board's policy at 500 Hz: settled for 5 s, then the first save of
    /// the run; the second 10 min later (the rate's zero has then learned for the 600 s
    /// a warm start counts it as, core `rate::ZERO_RESTORE_S`); then after each retune
    /// (once settled again) but at most every 10 min, and every hour regardless; 8 bytes
    /// programmed per tick (a 224-byte record in 28 ticks; firmware/docs/notes.md "Warm
    /// start on the stm32f405 board" has the timing and the write budget).
    pub const BOARD: SavePolicy = SavePolicy {
        hold_ticks: 5 * 500,
        min_interval_ticks: 10 * 60 * 500,
        refresh_ticks: 60 * 60 * 500,
        chunk_bytes: 8,
    };
}

/// What [`Saver::poll`] did this tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SaveEvent {
    /// Nothing (or a chunk of a save in progress).
    Idle,
    /// A save started: the record with this sequence number.
    Started(u32),
    /// The record with this sequence number is complete.
    Written(u32),
    /// A save could not start or was cut short (the previous record stays the newest).
    Failed(StoreError),
}

/// The board's save logic: when to save, and the save spread over ticks so that no
/// tick programs more than [`SavePolicy::chunk_bytes`] and nothing is erased in the
/// loop. Call [`Self::poll`] once per tick, after the tick's work.
#[derive(Clone, Copy, Debug)]
pub struct Saver {
    policy: SavePolicy,
    /// Tick since which the estimate is worth saving, without a break.
    settled_since: Option<u32>,
    /// Tick of the last save started (or failed) in this run.
    last_save: Option<u32>,
    /// The estimator's retune counter at the last save.
    retunes_at_save: u32,
    /// Records written in this run.
    pub written: u32,
    /// Saves that failed or could not start (saturates).
    pub failures: u32,
    /// The store is full for this run (both slots used; the next boot erases one).
    pub full: bool,
}

impl Saver {
    /// A saver at the start of a run (no save yet).
    pub fn new(policy: SavePolicy) -> Self {
        Saver {
            policy,
            settled_since: None,
            last_save: None,
            retunes_at_save: 0,
            written: 0,
            failures: 0,
            full: false,
        }
    }

    /// Whether a save is due at tick `now` for an estimate of health `h` and `retunes`
    /// retunes so far (also keeps track of how long it has been settled).
    #[inline(never)]
    pub fn due(&mut self, now: u32, h: &Health, retunes: u32) -> bool {
        let ok = h.settled && h.actionable();
        if !ok {
            self.settled_since = None;
            return false;
        }
        let since = *self.settled_since.get_or_insert(now);
        if self.full || now.wrapping_sub(since) < self.policy.hold_ticks {
            return false;
        }
        match self.last_save {
            None => true,
            Some(last) => {
                let age = now.wrapping_sub(last);
                // until the run has two records, a save every `min_interval_ticks` too:
                // the first is taken 5 s after the settle, when the rate's zero has
                // hardly learned, and a warm start carries that zero
                let news = retunes != self.retunes_at_save || self.written < 2;
                (news && age >= self.policy.min_interval_ticks) || age >= self.policy.refresh_ticks
            }
        }
    }

    /// One tick of the save logic: continues a save in progress, or starts one if it
    /// is due ([`Self::due`]).
    #[inline(never)]
    pub fn poll<F: NorFlash>(
        &mut self,
        store: &mut Store<F>,
        now: u32,
        est: &Estimator<f32>,
    ) -> SaveEvent {
        if store.busy() {
            return match store.continue_save(self.policy.chunk_bytes) {
                Ok(Some(seq)) => {
                    self.written = self.written.saturating_add(1);
                    SaveEvent::Written(seq)
                }
                Ok(None) => SaveEvent::Idle,
                Err(e) => self.failed(e),
            };
        }
        let retunes = est.counters().retunes;
        if !self.due(now, &est.health(), retunes) {
            return SaveEvent::Idle;
        }
        self.last_save = Some(now);
        self.retunes_at_save = retunes;
        match store.begin_save(&est.snapshot()) {
            Ok(seq) => SaveEvent::Started(seq),
            Err(e) => {
                self.full |= e == StoreError::NeedsErase;
                self.failed(e)
            }
        }
    }

    fn failed(&mut self, e: StoreError) -> SaveEvent {
        self.failures = self.failures.saturating_add(1);
        SaveEvent::Failed(e)
    }
}

/// What the board's boot did with the store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Boot {
    /// Warm, or cold with the reason (the flag).
    pub start: Start,
    /// The spare slot was erased now (`Ok(true)`), was blank already (`Ok(false)`), or
    /// could not be prepared (then the saves of this run fail and say so).
    pub prepared: Result<bool, StoreError>,
}

/// The board's boot: [`warm_start`] from the store, then [`Store::prepare`] (the only
/// erase of a run, before the loop starts).
#[inline(never)]
pub fn boot<F: NorFlash>(
    store: &mut Store<F>,
    est: &mut Estimator<f32>,
    temp_c: Option<f32>,
) -> Boot {
    let start = warm_start(store, est, temp_c);
    Boot {
        start,
        prepared: store.prepare(),
    }
}
