//! One record: the SI plant and the 14 lock-in ladders integrated together by the
//! adaptive Dormand–Prince pair ([`crate::dopri`]), one integration interval per sample
//! period, the pick-off noise added through its exact discretisation.
//!
//! # The lock-in front end (`paragyro-record 1`, from its specification)
//!
//! The reference phase ψ is half the pump phase: ψ' = π·`pump_hz`, with `pump_hz` linear
//! between two rows, so `ψ(t_k + τ) = ψ_k + π(f_k τ + (f_{k+1} − f_k)τ²/(2Ts))` exactly.
//! The measured displacements `xm`, `ym` are mixed with 1 (DC) and with `2e^{−ikψ}`
//! (k = 1, 2, 3), each product drives its own Butterworth ladder of the header's order
//! and cut-off ([`crate::ladder`]), and the ladders' outputs at the row instants are the
//! columns (µm): `x0 = LP[xm]`, `xk = LP[2·xm·e^{−ikψ}]` (re, im). The ladders start at
//! rest at t = 0 with ψ = 0.
//!
//! # Noise
//!
//! White displacement noise of one-sided density D on each pick-off. Mixed with the
//! references it gives, over the filters' band, independent white inputs of two-sided
//! density D²/2 on each DC channel and D² on each harmonic's re and im (⟨(2cos kψ)²⟩ = 2);
//! each is added as its own exactly discretised ladder process.

use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::Xoshiro256PlusPlus;

use crate::device::{L0_M, OMEGA0_RAD_S, SiDevice};
use crate::dopri::{Dopri, Stats, Tolerances};
use crate::effects::EffectSizes;
use crate::ladder::{Ladder, MAX_ORDER, NoiseDiscretisation};
use crate::plant::{Inputs, NQ, Plant};
use crate::protocol::Protocol;

/// Number of lock-in channels.
pub const NCH: usize = 14;

/// Settings of the front end and the numerics.
#[derive(Clone, Debug, PartialEq)]
pub struct FrontEnd {
    /// Low-pass order written to the header (1–8).
    pub lpf_order: usize,
    /// Low-pass cut-off written to the header, Hz.
    pub lpf_hz: f64,
    /// One-sided pick-off noise density, pm/√Hz (0: noise-free).
    pub noise_pm_rthz: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Relative tolerance of the integrator.
    pub rtol: f64,
    /// Initial drive displacement, m.
    pub x0_m: f64,
    /// The ladders' states enter the error control too (`false`: the plant's step, set by
    /// the plant's error alone, also integrates the ladders).
    pub control_lockin: bool,
}

impl Default for FrontEnd {
    /// 4th order, 150 Hz, 1 pm/√Hz, seed 1, rtol 1e-9, x(0) = 10 nm.
    fn default() -> Self {
        Self {
            lpf_order: 4,
            lpf_hz: 150.0,
            noise_pm_rthz: 1.0,
            seed: 1,
            rtol: 1e-9,
            x0_m: 0.01 * L0_M,
            control_lockin: false,
        }
    }
}

/// One row of a record.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Time, s.
    pub t_s: f64,
    /// Pump frequency in effect, Hz.
    pub pump_hz: f64,
    /// Pump voltage amplitude, V.
    pub pump_amp_v: f64,
    /// Accelerations, m/s².
    pub accel_mps2: [f64; 2],
    /// x0, x1 re/im … x3 re/im, y0, y1 re/im … y3 re/im, µm.
    pub lockin_um: [f64; NCH],
    /// Die temperature (0.01 K resolution), °C.
    pub temp_c: f64,
    /// The rate table's rate, °/s.
    pub rate_ref_dps: f64,
}

/// The 14 mixer products of `xm`, `ym` with the reference `e^{iψ}` = (c1, s1).
#[inline(always)]
fn mix(xm: f64, ym: f64, c1: f64, s1: f64) -> [f64; NCH] {
    // e^{−ikψ} = conj(e^{iψ})^k
    let (c2, s2) = (c1 * c1 - s1 * s1, 2.0 * s1 * c1);
    let (c3, s3) = (c2 * c1 - s2 * s1, s2 * c1 + c2 * s1);
    let (a, b) = (2.0 * xm, 2.0 * ym);
    [
        xm,
        a * c1,
        -a * s1,
        a * c2,
        -a * s2,
        a * c3,
        -a * s3,
        ym,
        b * c1,
        -b * s1,
        b * c2,
        -b * s2,
        b * c3,
        -b * s3,
    ]
}

/// Wraps a phase into [−π, π).
fn wrap(p: f64) -> f64 {
    p - std::f64::consts::TAU * ((p + std::f64::consts::PI) / std::f64::consts::TAU).floor()
}

/// What drives the lock-in: a plant (its states, their derivative, what the pick-offs
/// read), or a synthetic signal (the tests' tones).
pub trait Source {
    /// d/dt of the source's states.
    fn rhs(&self, t_s: f64, q: &[f64; NQ], u: &Inputs) -> [f64; NQ];
    /// What the pick-offs read, m, with the reference e^{iψ} = (`c1`, `s1`) at hand.
    fn measure(&self, t_s: f64, q: &[f64; NQ], u: &Inputs, c1: f64, s1: f64) -> [f64; 2];
}

impl Source for Plant {
    #[inline]
    fn rhs(&self, t_s: f64, q: &[f64; NQ], u: &Inputs) -> [f64; NQ] {
        Plant::rhs(self, t_s, q, u)
    }

    #[inline]
    fn measure(&self, _t_s: f64, q: &[f64; NQ], u: &Inputs, _c1: f64, _s1: f64) -> [f64; 2] {
        Plant::measure(self, q, u)
    }
}

/// The result of one simulated record.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The rows.
    pub rows: Vec<Row>,
    /// The integrator's counters.
    pub stats: Stats,
}

/// Simulates `proto` on the device `dev` with the effects `fx` through the front end `fe`
/// (whose low-pass is off by the effects' lock-in mismatch).
pub fn simulate(
    dev: &SiDevice,
    fx: &EffectSizes,
    proto: &Protocol,
    fe: &FrontEnd,
) -> Result<Simulated, String> {
    let plant = Plant::new(*dev, *fx, proto.pump_hz(0.0));
    let fe_true = FrontEnd {
        lpf_hz: fe.lpf_hz * (1.0 + fx.lockin_mismatch),
        ..fe.clone()
    };
    let mut q0 = [0.0; NQ];
    q0[0] = fe.x0_m;
    run(&plant, q0, proto, &fe_true)
}

/// The integrator's tolerances for `dim` states: 1e-11 µm on the plant's displacements
/// (velocities × ω0) with the relative tolerance on each oscillator's amplitude, the
/// ladders riding along (or, with `control_lockin`, each at 1e-6 µm).
fn tolerances(fe: &FrontEnd, dim: usize, ts: f64) -> Tolerances {
    let w0 = OMEGA0_RAD_S;
    let a_pos = 1e-11 * L0_M;
    let ladder_atol = if fe.control_lockin {
        1e-6 * L0_M
    } else {
        f64::INFINITY
    };
    let mut atol = vec![ladder_atol; dim];
    for (i, a) in atol.iter_mut().enumerate().take(NQ) {
        *a = if i % 2 == 1 { a_pos * w0 } else { a_pos };
    }
    Tolerances {
        rtol: fe.rtol,
        atol,
        h_max: ts / 4.0,
        pair_omega: (!fe.control_lockin).then_some(w0),
    }
}

/// The pick-off noise through the ladders, one exactly discretised process per channel.
struct NoiseBank {
    disc: NoiseDiscretisation,
    xi: Vec<[f64; MAX_ORDER]>,
    /// One-sided density, m/√Hz.
    density: f64,
    rng: Xoshiro256PlusPlus,
}

impl NoiseBank {
    fn new(ladder: &Ladder, ts: f64, fe: &FrontEnd) -> Self {
        Self {
            disc: NoiseDiscretisation::new(ladder, ts),
            xi: vec![[0.0; MAX_ORDER]; NCH],
            density: fe.noise_pm_rthz * 1e-12,
            rng: Xoshiro256PlusPlus::seed_from_u64(fe.seed),
        }
    }

    /// Advances every channel by one sample period.
    fn step(&mut self) {
        if self.density <= 0.0 {
            return;
        }
        let n = self.disc.n;
        let mut w = [0.0; MAX_ORDER];
        for (c, x) in self.xi.iter_mut().enumerate() {
            // two-sided densities: D²/2 on the DC channels, D² on each harmonic's re, im
            let sig = if c == 0 || c == 7 {
                self.density * std::f64::consts::FRAC_1_SQRT_2
            } else {
                self.density
            };
            for v in w.iter_mut().take(n) {
                *v = StandardNormal.sample(&mut self.rng);
            }
            self.disc.step(&mut x[..n], sig, &w[..n]);
        }
    }
}

/// The row of sample `k`: the protocol's inputs and the ladders' outputs (µm).
fn row(proto: &Protocol, k: usize, ladder: &Ladder, y: &[f64], noise: &NoiseBank) -> Row {
    let t = proto.t(k);
    let no = ladder.n;
    let mut li = [0.0; NCH];
    for (c, v) in li.iter_mut().enumerate() {
        // the ladders are stored state-major: the last state of channel c
        let out = 2.0 * y[NQ + (no - 1) * NCH + c];
        *v = (out + ladder.output(&noise.xi[c][..no])) / L0_M;
    }
    Row {
        t_s: t,
        pump_hz: proto.pump_hz(t),
        pump_amp_v: proto.pump_amp_ref_v * proto.pump_scale(t).sqrt(),
        accel_mps2: proto.accel(t),
        lockin_um: li,
        temp_c: (proto.temp_c(t) * 100.0).round() / 100.0,
        rate_ref_dps: proto.rate_dps(t).0,
    }
}

/// Runs the front end of `fe` (its `lpf_hz` is the true cut-off) on `src` started at `q0`
/// over the protocol `proto`.
pub fn run<S: Source>(
    src: &S,
    q0: [f64; NQ],
    proto: &Protocol,
    fe: &FrontEnd,
) -> Result<Simulated, String> {
    let n_int = proto.intervals();
    if n_int == 0 {
        return Err(format!(
            "duration {} s is shorter than one sample",
            proto.duration_s
        ));
    }
    let ts = 1.0 / proto.fs_hz;
    let ladder = Ladder::new(fe.lpf_order, fe.lpf_hz)?;
    let no = ladder.n;
    let mut noise = NoiseBank::new(&ladder, ts, fe);
    let dim = NQ + NCH * no;
    let mut y0 = vec![0.0; dim];
    y0[..NQ].copy_from_slice(&q0);
    let mut ode = Dopri::new(0.0, y0, tolerances(fe, dim, ts), 1e-6);
    let mut rows = Vec::with_capacity(n_int + 1);
    rows.push(row(proto, 0, &ladder, &ode.y, &noise));
    let mut psi_k = 0.0;
    for k in 0..n_int {
        let (t0, t1) = (proto.t(k), proto.t(k + 1));
        let (f0, f1) = (proto.pump_hz(t0), proto.pump_hz(t1));
        let (s0, s1) = (proto.pump_scale(t0), proto.pump_scale(t1));
        let (a0, a1) = (proto.accel(t0), proto.accel(t1));
        let chirp = (f1 - f0) / ts;
        let mut rhs = |t: f64, y: &[f64], dy: &mut [f64]| {
            let tau = t - t0;
            let frac = tau / ts;
            // ψ' = π·pump_hz, pump_hz linear over the interval: ψ exact
            let psi = psi_k + std::f64::consts::PI * tau * (f0 + 0.5 * chirp * tau);
            let (sn, cs) = psi.sin_cos();
            let (r, rd) = proto.rate_dps(t);
            let u = Inputs {
                cos2psi: cs * cs - sn * sn,
                s: s0 + (s1 - s0) * frac,
                ax: a0[0] + (a1[0] - a0[0]) * frac,
                ay: a0[1] + (a1[1] - a0[1]) * frac,
                rate: r.to_radians(),
                rate_dot: rd.to_radians(),
                temp_c: proto.temp_c(t),
            };
            let q: &[f64; NQ] = y[..NQ].try_into().expect("plant states");
            dy[..NQ].copy_from_slice(&src.rhs(t, q, &u));
            let [xm, ym] = src.measure(t, q, &u, cs, sn);
            ladder.deriv_bank(&y[NQ..], &mix(xm, ym, cs, sn), &mut dy[NQ..]);
        };
        ode.advance_to(t1, &mut rhs);
        if !ode.y.iter().all(|v| v.is_finite()) {
            return Err(format!("the state is not finite at t = {t1} s"));
        }
        psi_k = wrap(psi_k + std::f64::consts::PI * ts * 0.5 * (f0 + f1));
        noise.step();
        rows.push(row(proto, k + 1, &ladder, &ode.y, &noise));
    }
    Ok(Simulated {
        rows,
        stats: ode.stats,
    })
}
