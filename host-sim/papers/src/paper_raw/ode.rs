//! The combined ODE: plant (4) + Λ filters (8 × 2) + θ1 (8) + P1 (64) + θ2 (6) + P2 (36),
//! its right-hand side (eqs. 6, 10, 17) and one classic RK4 step.

use paragyro_simulator::plant::Theta;

use super::config::{LAMBDA_A0, LAMBDA_A1, ZForm};

/// Classic RK4 is stable for y' = −a·y, a > 0, only while h·a ≲ 2.785. Along Φ, θ̂' = PΦe
/// has the rate ΦᵀPΦ and the linearised Riccati equation P' = λP − PΦΦᵀP up to 2ΦᵀPΦ.
pub const RK4_STABILITY_LIMIT: f64 = 2.785;

/// Filtered signals, in this order.
const F_X: usize = 0;
const F_Y: usize = 1;
const F_X3: usize = 2;
const F_XC: usize = 3;
const F_X3C: usize = 4;
const F_AX: usize = 5;
const F_Y3: usize = 6;
const F_AY: usize = 7;
const NF: usize = 8;

pub(super) const I_Z: usize = 0;
pub(super) const I_F: usize = 4;
pub(super) const I_T1: usize = I_F + 2 * NF;
pub(super) const I_P1: usize = I_T1 + 8;
pub(super) const I_T2: usize = I_P1 + 64;
pub(super) const I_P2: usize = I_T2 + 6;
/// Size of the combined state.
pub(super) const NS: usize = I_P2 + 36;

pub(super) type State = [f64; NS];

/// What the right-hand side needs besides the state, at one stage.
#[derive(Clone, Copy)]
pub(super) struct Stage<'a> {
    pub(super) theta: &'a Theta,
    /// θ of the equation-error diagnostic.
    pub(super) model: &'a Theta,
    pub(super) cos2psi: f64,
    pub(super) noise: [f64; 2],
    pub(super) accel: [f64; 2],
    pub(super) lambda: f64,
    pub(super) z_form: ZForm,
}

/// Diagnostics of one evaluation of the right-hand side.
#[derive(Clone, Copy, Default)]
pub(super) struct Diag {
    /// Estimator errors e1, e2 (eq. 13).
    pub(super) e: [f64; 2],
    /// Equation errors with the true θ: Z − Φᵀθ_true (shifted as the estimator's θ).
    pub(super) e_true: [f64; 2],
    /// The measurements Z1, Z2.
    pub(super) z: [f64; 2],
    /// Φᵀ P Φ (the stiffness of the Riccati equation along Φ).
    pub(super) phi_p_phi: [f64; 2],
}

/// Regressors Φ1, Φ2 (eq. 25 order) from the filter states.
#[inline(always)]
pub(super) fn regressors(y: &State) -> ([f64; 8], [f64; 6]) {
    let s = |j: usize| y[I_F + 2 * j];
    let ds = |j: usize| y[I_F + 2 * j + 1];
    (
        [
            ds(F_X),
            s(F_X),
            s(F_Y),
            ds(F_Y),
            s(F_X3),
            s(F_XC),
            s(F_X3C),
            s(F_AX),
        ],
        [ds(F_Y), s(F_Y), s(F_X), ds(F_X), s(F_Y3), s(F_AY)],
    )
}

/// The shift between the estimator's vector and the eq. (25) θ ([3, 2, 0, …] for
/// [`ZForm::Literal`], 0 for [`ZForm::D2`]).
pub(super) fn shift(z_form: ZForm) -> f64 {
    match z_form {
        ZForm::Literal => 1.0,
        ZForm::D2 => 0.0,
    }
}

/// One axis of eq. (10): writes θ̂' and P' into `dth`, `dp`; returns (e, ΦᵀPΦ).
#[inline(always)]
fn ls_axis<const N: usize>(
    th: &[f64],
    p: &[f64],
    phi: &[f64; N],
    z: f64,
    lambda: f64,
    dth: &mut [f64],
    dp: &mut [f64],
) -> (f64, f64) {
    let mut e = z;
    for i in 0..N {
        e -= phi[i] * th[i];
    }
    let mut v = [0.0; N];
    for i in 0..N {
        let row = &p[i * N..(i + 1) * N];
        let mut acc = 0.0;
        for j in 0..N {
            acc += row[j] * phi[j];
        }
        v[i] = acc;
    }
    let mut pp = 0.0;
    for i in 0..N {
        pp += phi[i] * v[i];
        dth[i] = v[i] * e;
        let row = &p[i * N..(i + 1) * N];
        let drow = &mut dp[i * N..(i + 1) * N];
        for j in 0..N {
            drow[j] = lambda * row[j] - v[i] * v[j];
        }
    }
    (e, pp)
}

/// d/dτ of the combined state. With `EST = false` the estimator (θ̂, P) is frozen.
#[inline(always)]
fn rhs<const EST: bool>(y: &State, st: &Stage<'_>, dy: &mut State) -> Diag {
    let [x, xd, yv, yd] = [y[0], y[1], y[2], y[3]];
    let t1 = &st.theta.drive;
    let t2 = &st.theta.sense;
    let c = st.cos2psi;
    let [ax, ay] = st.accel;
    // ---- plant, eq. (6) (s = 1)
    let x3 = x * x * x;
    dy[I_Z] = xd;
    dy[I_Z + 1] = (t1[0] * xd + t1[3] * yd)
        + (t1[2] * yv + t1[7] * ax)
        + x * (t1[1] + t1[5] * c)
        + x3 * (t1[4] + t1[6] * c);
    dy[I_Z + 2] = yd;
    dy[I_Z + 3] =
        (t2[0] * yd + t2[3] * xd) + (t2[2] * x + t2[5] * ay) + yv * (t2[1] + t2[4] * (yv * yv));
    // ---- the measurement and the filter inputs (eq. 17)
    let xm = x + st.noise[0];
    let ym = yv + st.noise[1];
    let xm3 = xm * xm * xm;
    let u: [f64; NF] = [xm, ym, xm3, xm * c, xm3 * c, ax, ym * ym * ym, ay];
    for j in 0..NF {
        let s = y[I_F + 2 * j];
        let ds = y[I_F + 2 * j + 1];
        dy[I_F + 2 * j] = ds;
        dy[I_F + 2 * j + 1] = u[j] - LAMBDA_A1 * ds - LAMBDA_A0 * s;
    }
    // ---- measurements Z (module docs)
    let (phi1, phi2) = regressors(y);
    let sh = shift(st.z_form);
    let (z1, z2) = match st.z_form {
        ZForm::Literal => (xm, ym),
        ZForm::D2 => (
            xm - LAMBDA_A1 * phi1[0] - LAMBDA_A0 * phi1[1],
            ym - LAMBDA_A1 * phi2[0] - LAMBDA_A0 * phi2[1],
        ),
    };
    // equation errors with the model θ (shifted like the estimator's vector)
    let (m1, m2) = (&st.model.drive, &st.model.sense);
    let mut et1 = z1 - sh * (LAMBDA_A1 * phi1[0] + LAMBDA_A0 * phi1[1]);
    for i in 0..8 {
        et1 -= phi1[i] * m1[i];
    }
    let mut et2 = z2 - sh * (LAMBDA_A1 * phi2[0] + LAMBDA_A0 * phi2[1]);
    for i in 0..6 {
        et2 -= phi2[i] * m2[i];
    }
    let mut d = Diag {
        e_true: [et1, et2],
        z: [z1, z2],
        ..Diag::default()
    };
    // ---- eq. (10), both axes
    if EST {
        let (a, b) = dy.split_at_mut(I_P1);
        let (e1, pp1) = ls_axis::<8>(
            &y[I_T1..I_T1 + 8],
            &y[I_P1..I_P1 + 64],
            &phi1,
            z1,
            st.lambda,
            &mut a[I_T1..I_T1 + 8],
            &mut b[..64],
        );
        let (a, b) = dy.split_at_mut(I_P2);
        let (e2, pp2) = ls_axis::<6>(
            &y[I_T2..I_T2 + 6],
            &y[I_P2..I_P2 + 36],
            &phi2,
            z2,
            st.lambda,
            &mut a[I_T2..I_T2 + 6],
            &mut b[..36],
        );
        d.e = [e1, e2];
        d.phi_p_phi = [pp1, pp2];
    } else {
        dy[I_T1..].fill(0.0);
    }
    d
}

/// One classic RK4 step of the combined state; returns the diagnostics at the step start.
#[inline(always)]
pub(super) fn rk4<const EST: bool>(
    y: &mut State,
    h: f64,
    sa: &Stage<'_>,
    sm: &Stage<'_>,
    se: &Stage<'_>,
) -> Diag {
    let mut k1 = [0.0; NS];
    let mut k2 = [0.0; NS];
    let mut k3 = [0.0; NS];
    let mut k4 = [0.0; NS];
    let mut yt = [0.0; NS];
    let hh = 0.5 * h;
    let d = rhs::<EST>(y, sa, &mut k1);
    for i in 0..NS {
        yt[i] = y[i] + hh * k1[i];
    }
    rhs::<EST>(&yt, sm, &mut k2);
    for i in 0..NS {
        yt[i] = y[i] + hh * k2[i];
    }
    rhs::<EST>(&yt, sm, &mut k3);
    for i in 0..NS {
        yt[i] = y[i] + h * k3[i];
    }
    rhs::<EST>(&yt, se, &mut k4);
    let h6 = h / 6.0;
    for i in 0..NS {
        y[i] += h6 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i]);
    }
    d
}
