//! Warm start: a snapshot of the converged estimate that survives a reset.
//!
//! A [`Snapshot`] holds what the estimator learned and a boot cannot re-derive quickly:
//! θ̂1, θ̂2 (the linearisation point to start from), the pump centre, the traces of the
//! two covariances, the health when it was taken, the die temperature and the learned
//! temperature coefficients, and the rate's zero with its count (a warm start goes on with
//! that mean, counted as at most [`crate::rate::ZERO_RESTORE_S`] of updates). [`Snapshot::encode`] writes it as
//! [`SNAPSHOT_LEN`] little-endian bytes with a magic, a [`SNAPSHOT_VERSION`], a CRC of
//! the configuration it was taken under and a CRC-32 over everything;
//! [`Snapshot::decode`] refuses anything else with a [`SnapshotError`].
//!
//! [`Estimator::warm_start`] applies a snapshot to a freshly built estimator: the RLS
//! linearises about the stored θ̂ (δθ = 0), its covariance restarts at the stored
//! trace per parameter (bounded by `rls.p_reset`), and the pump centre jumps to the
//! stored one. The start-up gate still runs, shortened to [`WARM_GATE_S`] (the filters
//! need it, the identification does not: measured), and the first settle starts from the
//! restored ω̂y² ([`WARM_SETTLE_NEW`]). If the device
//! changed while it was off, the change detector resets the covariance as after any
//! change. [`Estimator::boot_from`] is the boot path: a missing, corrupt, foreign or
//! implausible record leaves the design values and says why ([`Start::Cold`]).
//!
//! No allocation, no panic; the codec is `no_std` and the firmware stores its bytes
//! (firmware/src/persist.rs).

use crate::config::Config;
use crate::drift::DRIFT_COL;
use crate::estimator::Estimator;
use crate::physics::theta_from_physical;
use crate::real::Real;

/// Bytes of an encoded snapshot.
pub const SNAPSHOT_LEN: usize = 212;
/// Version of the encoding (bumped whenever the layout or the meaning changes).
pub const SNAPSHOT_VERSION: u16 = 3;
/// Magic at the start of a record.
pub const SNAPSHOT_MAGIC: [u8; 4] = *b"PGWS";
/// Smallest restored covariance per parameter (scaled units; the RLS must still move).
pub const WARM_P_MIN: f64 = 1e-9;
/// The start-up gate of a warm start, s (the design's `monitor.gate_startup_s` is 0.5 s):
/// the rows' filters and the plant's start-up transient still need it, but not the
/// identification. Measured (`cargo test -p paragyro-simulator --lib warm_gates_swept --
/// --ignored --nocapture`, identify, seeds 13–15, dither on and off): with 0.25 s the warm
/// estimate stays within the floors from the first tick as with 0.5 s; with 0.1 s the
/// first updates on transient rows pushed it out (back after 1.03 s, or never).
pub const WARM_GATE_S: f64 = 0.25;
/// The first settle of a warm start: the settle test's history starts with the restored
/// ω̂y² in all but this many places, and the settle window counts from the end of the warm
/// gate. So `WARM_SETTLE_NEW` fresh ω̂y² values (one every 25 samples, 0.05 s) that agree
/// with the restored one and with each other declare it settled; values that disagree (the
/// device changed while off) flush the restored ones as from a cold start. Later settles
/// (after a reset) use the design's window.
pub const WARM_SETTLE_NEW: usize = 2;
/// A stored pump centre further than this (relative) from the configured one is
/// implausible.
pub const WARM_PUMP_TOL: f64 = 0.05;

/// The learned state a warm start restores.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snapshot {
    /// CRC-32 of the configuration it was taken under ([`config_crc`]).
    pub config_crc: u32,
    /// `Health::bits` when it was taken.
    pub health_bits: u32,
    /// θ̂1 (eq. 25 order).
    pub theta1: [f64; 8],
    /// θ̂2.
    pub theta2: [f64; 6],
    /// Pump centre, Hz.
    pub pump_centre_hz: f64,
    /// Traces of the column-scaled covariances (drive, sense).
    pub traces: [f64; 2],
    /// The die temperature when it was taken, °C (NaN: no sensor).
    pub temp_c: f64,
    /// The learned temperature coefficients of θ12 and θ22, per K (module
    /// [`crate::thermal`]; NaN where not learned).
    pub dtheta_dt: [f64; 2],
    /// Their variances, per K².
    pub dtheta_dt_var: [f64; 2],
    /// The rate's zero μxy and the settled updates in its mean (0: none yet; module
    /// [`crate::rate`]): a warm start goes on with that mean, counted as at most
    /// [`crate::rate::ZERO_RESTORE_S`] of updates.
    pub zero: [f64; 2],
}

/// Why a record was not used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SnapshotError {
    /// There is no record (empty store).
    Missing,
    /// The store could not be read (a flash error).
    Unreadable,
    /// Fewer than [`SNAPSHOT_LEN`] bytes.
    Short,
    /// Not a snapshot (magic or length field wrong).
    Magic,
    /// Another encoding version.
    Version(u16),
    /// The CRC does not match: a torn or corrupted record.
    Crc,
    /// Taken under another configuration.
    Config,
    /// Non-finite, not settled, or too far from the design to trust.
    Implausible,
}

/// How the estimator started.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Start {
    /// From a stored snapshot.
    Warm,
    /// From the design values, because the record was unusable (the flag).
    Cold(SnapshotError),
}

/// CRC-32 (IEEE 802.3, reflected, as zlib's `crc32`), bitwise: small, and only run at
/// boot and when a record is written.
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for b in bytes {
        c ^= *b as u32;
        for _ in 0..8 {
            let mask = (c & 1).wrapping_neg();
            c = (c >> 1) ^ (0xEDB8_8320 & mask);
        }
    }
    !c
}

/// CRC-32 of the configuration values a snapshot depends on: f0, fs, L0, the pump
/// centre and the nominal design.
#[inline(never)]
pub fn config_crc(cfg: &Config) -> u32 {
    let mut buf = [0u8; 8 * 16];
    let vals = [cfg.f0_hz, cfg.fs_hz, cfg.l0_um, cfg.pump_centre_hz];
    let nominal = cfg.nominal.as_array();
    for (i, v) in vals.iter().chain(nominal.iter()).enumerate() {
        buf[8 * i..8 * i + 8].copy_from_slice(&v.to_le_bytes());
    }
    crc32(&buf)
}

/// Little-endian writer/reader over a fixed buffer (offsets are constants: no bounds
/// can fail).
struct Cursor<'a, B> {
    buf: B,
    at: usize,
    _l: core::marker::PhantomData<&'a ()>,
}

impl<'a> Cursor<'a, &'a mut [u8; SNAPSHOT_LEN]> {
    fn put(&mut self, b: &[u8]) {
        self.buf[self.at..self.at + b.len()].copy_from_slice(b);
        self.at += b.len();
    }
}

impl<'a> Cursor<'a, &'a [u8; SNAPSHOT_LEN]> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut out = [0u8; N];
        out.copy_from_slice(&self.buf[self.at..self.at + N]);
        self.at += N;
        out
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
}

impl Snapshot {
    /// The record: magic, version, length, the fields, CRC-32 of all before it.
    #[inline(never)]
    pub fn encode(&self) -> [u8; SNAPSHOT_LEN] {
        let mut out = [0u8; SNAPSHOT_LEN];
        let mut w = Cursor {
            buf: &mut out,
            at: 0,
            _l: core::marker::PhantomData,
        };
        w.put(&SNAPSHOT_MAGIC);
        w.put(&SNAPSHOT_VERSION.to_le_bytes());
        w.put(&(SNAPSHOT_LEN as u16).to_le_bytes());
        w.put(&self.config_crc.to_le_bytes());
        w.put(&self.health_bits.to_le_bytes());
        for v in self.theta1.iter().chain(self.theta2.iter()) {
            w.put(&v.to_le_bytes());
        }
        w.put(&self.pump_centre_hz.to_le_bytes());
        w.put(&self.traces[0].to_le_bytes());
        w.put(&self.traces[1].to_le_bytes());
        for v in [
            self.temp_c,
            self.dtheta_dt[0],
            self.dtheta_dt[1],
            self.dtheta_dt_var[0],
            self.dtheta_dt_var[1],
            self.zero[0],
            self.zero[1],
        ] {
            w.put(&v.to_le_bytes());
        }
        let crc = crc32(&w.buf[..SNAPSHOT_LEN - 4]);
        w.put(&crc.to_le_bytes());
        out
    }

    /// Reads a record (the first [`SNAPSHOT_LEN`] bytes of `bytes`); checks the magic,
    /// the version and the CRC.
    #[inline(never)]
    pub fn decode(bytes: &[u8]) -> Result<Snapshot, SnapshotError> {
        let Some(rec) = bytes.first_chunk::<SNAPSHOT_LEN>() else {
            return Err(SnapshotError::Short);
        };
        let mut r = Cursor {
            buf: rec,
            at: 0,
            _l: core::marker::PhantomData,
        };
        let magic: [u8; 4] = r.take();
        let version = u16::from_le_bytes(r.take());
        let len = u16::from_le_bytes(r.take());
        if magic != SNAPSHOT_MAGIC {
            return Err(SnapshotError::Magic);
        }
        if version != SNAPSHOT_VERSION {
            return Err(SnapshotError::Version(version));
        }
        if len as usize != SNAPSHOT_LEN {
            return Err(SnapshotError::Magic);
        }
        let crc = u32::from_le_bytes(*rec.last_chunk::<4>().unwrap_or(&[0; 4]));
        if crc32(&rec[..SNAPSHOT_LEN - 4]) != crc {
            return Err(SnapshotError::Crc);
        }
        let config_crc = u32::from_le_bytes(r.take());
        let health_bits = u32::from_le_bytes(r.take());
        let theta1 = core::array::from_fn(|_| r.f64());
        let theta2 = core::array::from_fn(|_| r.f64());
        let pump_centre_hz = r.f64();
        let traces = [r.f64(), r.f64()];
        let temp_c = r.f64();
        let dtheta_dt = [r.f64(), r.f64()];
        let dtheta_dt_var = [r.f64(), r.f64()];
        let zero = [r.f64(), r.f64()];
        Ok(Snapshot {
            config_crc,
            health_bits,
            theta1,
            theta2,
            pump_centre_hz,
            traces,
            temp_c,
            dtheta_dt,
            dtheta_dt_var,
            zero,
        })
    }
}

/// Bit of `Health::bits` that says settled.
const SETTLED_BIT: u32 = 1 << 5;

impl<T: Real> Estimator<T> {
    /// The current estimate as a snapshot (take it when the health is settled: a
    /// snapshot that was not is refused at boot).
    #[inline(never)]
    pub fn snapshot(&self) -> Snapshot {
        let (theta1, theta2) = self.theta();
        let (temp_c, dtheta_dt, dtheta_dt_var) = self.thermal_record();
        let (mu_xy, n) = self.rate_zero();
        Snapshot {
            config_crc: config_crc(self.config()),
            health_bits: self.health().bits(),
            theta1,
            theta2,
            pump_centre_hz: self.pump_centre_hz(),
            traces: [self.traces().0, self.traces().1],
            temp_c,
            dtheta_dt,
            dtheta_dt_var,
            zero: [mu_xy, n],
        }
    }

    /// Checks that `snap` fits this estimator: its configuration, settled when taken,
    /// finite, every θ within 2|θ_design| of the design (the re-linearisation's own
    /// bound) and the pump centre within [`WARM_PUMP_TOL`] of the configured one.
    #[inline(never)]
    pub fn check_snapshot(&self, snap: &Snapshot) -> Result<(), SnapshotError> {
        let cfg = self.config();
        if snap.config_crc != config_crc(cfg) {
            return Err(SnapshotError::Config);
        }
        let (d1, d2) = theta_from_physical(&cfg.nominal);
        let near = |v: f64, d: f64| v.is_finite() && libm::fabs(v - d) <= 2.0 * libm::fabs(d);
        let thetas_ok = snap.theta1.iter().zip(d1.iter()).all(|(v, d)| near(*v, *d))
            && snap.theta2.iter().zip(d2.iter()).all(|(v, d)| near(*v, *d));
        let centre = cfg.pump_centre_hz;
        let pump_ok = snap.pump_centre_hz.is_finite()
            && libm::fabs(snap.pump_centre_hz - centre) <= WARM_PUMP_TOL * centre;
        let traces_ok = snap.traces.iter().all(|t| t.is_finite() && *t > 0.0);
        if snap.health_bits & SETTLED_BIT == 0 || !thetas_ok || !pump_ok || !traces_ok {
            return Err(SnapshotError::Implausible);
        }
        Ok(())
    }

    /// Starts warm from `snap` (call on a freshly built estimator, before the first
    /// step): linearises about the stored θ̂, restarts the covariances at the stored
    /// trace per parameter (within [[`WARM_P_MIN`], `rls.p_reset`]), jumps the pump
    /// centre to the stored one and shortens the start-up gate to [`WARM_GATE_S`].
    /// Refused (nothing changed) if [`Self::check_snapshot`] fails.
    #[inline(never)]
    pub fn warm_start(&mut self, snap: &Snapshot) -> Result<(), SnapshotError> {
        self.warm_start_at(snap, None)
    }

    /// [`Self::warm_start`] at the die temperature `temp_c` (°C, `None`: unknown).
    /// Where the record holds learned temperature coefficients and the temperature it
    /// was taken at, θ12 and θ22 start moved to `temp_c` (θ + dθ/dT·ΔT) and the pump
    /// centre at twice the sense resonance there, 2·f0·√ω̂y²(T); the learner keeps the
    /// coefficients
    /// (learned, with their variances) and refers them to `temp_c`. Without either
    /// temperature, or coefficients, the stored θ̂ as taken.
    #[inline(never)]
    pub fn warm_start_at(
        &mut self,
        snap: &Snapshot,
        temp_c: Option<f64>,
    ) -> Result<(), SnapshotError> {
        self.check_snapshot(snap)?;
        let snap = &self.at_temperature(snap, temp_c);
        self.check_snapshot(snap)?;
        let p_reset = self.config().rls.p_reset;
        let (d, st) = self.parts_mut();
        let om_ref = d.units.om_ref;
        st.rows.relinearize(&snap.theta1, &snap.theta2, om_ref);
        st.lin.move_to(snap.theta1, snap.theta2);
        st.rls1.set_estimate([T::ZERO; 8]);
        st.rls2.set_estimate([T::ZERO; 6]);
        // max/min, not f64::clamp: its NaN/ordering assertion formats f64s and pulled
        // ≈ 10 KB of float formatting into the stm32f405 image
        let p_max = p_reset.max(WARM_P_MIN);
        let p = |tr: f64, n: f64| T::from_f64((tr / n).max(WARM_P_MIN).min(p_max));
        st.rls1.reset_covariance(p(snap.traces[0], 8.0));
        st.rls2.reset_covariance(p(snap.traces[1], 6.0));
        st.rate
            .restore_zero(snap.zero[0], snap.zero[1], d.cfg.fs_hz);
        st.sched
            .jump(snap.pump_centre_hz / (2.0 * d.units.f0_hz) - om_ref);
        let sc = [d.fit.sc1[DRIFT_COL].to_f64(), d.fit.sc2[DRIFT_COL].to_f64()];
        st.thermal
            .restore(temp_c, snap.dtheta_dt, snap.dtheta_dt_var, sc);
        let fs = self.config().fs_hz;
        let wy2 = T::from_f64(self.wy2());
        let w = &mut self.design_mut().watch;
        w.gate_startup = w.gate_startup.min((WARM_GATE_S * fs) as u64);
        let settle = w.settle;
        let (_, st) = self.parts_mut();
        st.warm_first = true;
        let keep = settle.need().saturating_sub(WARM_SETTLE_NEW);
        st.settle.seed(&settle, wy2, keep);
        Ok(())
    }

    /// For measurements only (`warm_gates_swept`): the start-up gate and the settle
    /// window set to `gate_s` and `window_s` (the settle window then holds for the whole
    /// run, after every reset too).
    pub fn set_start_gates(&mut self, gate_s: f64, window_s: f64) {
        let fs = self.config().fs_hz;
        let tol = self.config().retune.settle_tol;
        let w = &mut self.design_mut().watch;
        w.gate_startup = (gate_s * fs) as u64;
        let need = ((window_s * fs) / crate::estimator::SETTLE_EVERY as f64) as usize + 1;
        w.settle = crate::monitor::SettleDesign::new(crate::estimator::SETTLE_EVERY, need, tol);
        w.settle_window = (window_s * fs) as u64;
    }

    /// The boot path: a warm start from `record` (the stored bytes, `None` if the store
    /// is empty), or the design values and the reason ([`Start::Cold`]).
    #[inline(never)]
    pub fn boot_from(&mut self, record: Option<&[u8]>) -> Start {
        self.boot_from_at(record, None)
    }

    /// [`Self::boot_from`] at the die temperature `temp_c` (°C; the board reads its
    /// sensor before the first tick): [`Self::warm_start_at`].
    #[inline(never)]
    pub fn boot_from_at(&mut self, record: Option<&[u8]>, temp_c: Option<f64>) -> Start {
        let snap = match record.map(Snapshot::decode) {
            None => return Start::Cold(SnapshotError::Missing),
            Some(Err(e)) => return Start::Cold(e),
            Some(Ok(s)) => s,
        };
        match self.warm_start_at(&snap, temp_c) {
            Ok(()) => Start::Warm,
            Err(e) => Start::Cold(e),
        }
    }

    /// `snap` moved to the die temperature `temp_c` with its own coefficients (module
    /// docs of [`Self::warm_start_at`]); unchanged where a temperature or a coefficient
    /// is missing.
    fn at_temperature(&self, snap: &Snapshot, temp_c: Option<f64>) -> Snapshot {
        let dt = temp_c.map_or(f64::NAN, |t| t - snap.temp_c);
        let ok = |v: f64| v.is_finite();
        if !(ok(dt) && snap.dtheta_dt.iter().all(|v| ok(*v))) {
            return *snap;
        }
        let mut s = *snap;
        s.theta1[1] += snap.dtheta_dt[0] * dt;
        s.theta2[1] += snap.dtheta_dt[1] * dt;
        // the pump at twice the sense resonance there (where the retune would put it;
        // the stored centre may sit up to the retune's deadband off)
        let wy2_t = crate::physics::wy2_from_theta(&s.theta1, &s.theta2);
        if wy2_t > 0.0 {
            s.pump_centre_hz = 2.0 * self.config().f0_hz * libm::sqrt(wy2_t);
        }
        s.temp_c = temp_c.unwrap_or(f64::NAN);
        s
    }
}

#[cfg(test)]
mod tests;
