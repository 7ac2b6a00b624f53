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

/// The result of one simulated record.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The rows.
    pub rows: Vec<Row>,
    /// The integrator's counters.
    pub stats: Stats,
}

/// Simulates `proto` on the device `dev` with the effects `fx` through the front end `fe`.
pub fn simulate(
    dev: &SiDevice,
    fx: &EffectSizes,
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
    let lp_true = fe.lpf_hz * (1.0 + fx.lockin_mismatch);
    let ladder = Ladder::new(fe.lpf_order, lp_true)?;
    let no = ladder.n;
    let noise_disc = NoiseDiscretisation::new(&ladder, ts);
    let d_m = fe.noise_pm_rthz * 1e-12; // one-sided, m/√Hz
    let sig_dc = d_m / std::f64::consts::SQRT_2;
    let sig_h = d_m;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(fe.seed);
    let plant = Plant::new(*dev, *fx, proto.pump_hz(0.0));

    let dim = NQ + NCH * no;
    let mut y0 = vec![0.0; dim];
    y0[0] = fe.x0_m;
    let w0 = OMEGA0_RAD_S;
    // absolute tolerances: 1e-8 µm on the plant's displacements (velocities × ω0), 1e-6 µm
    // on the ladders (a tenth of a percent of one sample's noise; the ladders forget an
    // error within a few ms, and their mixer inputs are µm-sized even where the filtered
    // output is near zero)
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
    let tol = Tolerances {
        rtol: fe.rtol,
        atol,
        h_max: ts / 4.0,
        pair_omega: (!fe.control_lockin).then_some(w0),
    };
    let mut ode = Dopri::new(0.0, y0, tol, 1e-6);

    let mut xi = vec![[0.0; MAX_ORDER]; NCH];
    let mut rows = Vec::with_capacity(n_int + 1);
    let mut psi_k = 0.0;
    let row = |k: usize, ode: &Dopri, xi: &[[f64; MAX_ORDER]]| {
        let t = proto.t(k);
        let mut li = [0.0; NCH];
        for (c, v) in li.iter_mut().enumerate() {
            let s = &ode.y[NQ + c * no..NQ + (c + 1) * no];
            *v = (ladder.output(s) + ladder.output(&xi[c][..no])) / L0_M;
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
    };
    rows.push(row(0, &ode, &xi));
    let mut wbuf = [0.0; MAX_ORDER];
    for k in 0..n_int {
        let (t0, t1) = (proto.t(k), proto.t(k + 1));
        let (f0, f1) = (proto.pump_hz(t0), proto.pump_hz(t1));
        let (s0, s1) = (proto.pump_scale(t0), proto.pump_scale(t1));
        let (a0, a1) = (proto.accel(t0), proto.accel(t1));
        let chirp = (f1 - f0) / ts;
        let mut rhs = |t: f64, y: &[f64], dy: &mut [f64]| {
            let tau = t - t0;
            let frac = tau / ts;
            let psi = psi_k + std::f64::consts::PI * tau * (f0 + 0.5 * chirp * tau);
            let (s1p, c1p) = psi.sin_cos();
            let (r, rd) = proto.rate_dps(t);
            let u = Inputs {
                cos2psi: c1p * c1p - s1p * s1p,
                s: s0 + (s1 - s0) * frac,
                ax: a0[0] + (a1[0] - a0[0]) * frac,
                ay: a0[1] + (a1[1] - a0[1]) * frac,
                rate: r.to_radians(),
                rate_dot: rd.to_radians(),
                temp_c: proto.temp_c(t),
            };
            let q: &[f64; NQ] = y[..NQ].try_into().expect("plant states");
            let dq = plant.rhs(t, q, &u);
            dy[..NQ].copy_from_slice(&dq);
            let [xm, ym] = plant.measure(q, &u);
            let m = mix(xm, ym, c1p, s1p);
            for (c, mc) in m.iter().enumerate() {
                let off = NQ + c * no;
                ladder.deriv(&y[off..off + no], *mc, &mut dy[off..off + no]);
            }
        };
        ode.advance_to(t1, &mut rhs);
        if !ode.y.iter().all(|v| v.is_finite()) {
            return Err(format!("the state is not finite at t = {t1} s"));
        }
        psi_k = wrap(psi_k + std::f64::consts::PI * ts * 0.5 * (f0 + f1));
        if d_m > 0.0 {
            for (c, x) in xi.iter_mut().enumerate() {
                let sig = if c == 0 || c == 7 { sig_dc } else { sig_h };
                for w in wbuf.iter_mut().take(no) {
                    *w = StandardNormal.sample(&mut rng);
                }
                noise_disc.step(&mut x[..no], sig, &wbuf[..no]);
            }
        }
        rows.push(row(k + 1, &ode, &xi));
    }
    Ok(Simulated {
        rows,
        stats: ode.stats,
    })
}
