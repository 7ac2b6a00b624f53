//! The regression rows: 5 per axis per sample (DC; fundamental Re, Im; 3rd harmonic
//! Re, Im), exactly linear in the paper's θ1 (8) and θ2 (6) in eq. (25) order
//! (DERIVATION §2).
//!
//! Harmonic-k drive row, after the state-variable filter (`F0, F1, F2` = `w²/Λ`,
//! `w²D/Λ`, `w²D²/Λ`):
//!
//! ```text
//! F2(A) + 2ik F1(ωA) − ik F0(ω′A) − k² F0(ω²A)
//!   = θ11 [F1(A) + ik F0(ωA)] + θ12 F0(A) + θ13 F0(B) + θ14 [F1(B) + ik F0(ωB)]
//!   + θ15 F0([X³]_k) + θ16 F0(s[Xc]_k + (s−1)A) + θ17 F0(s[X³c]_k + (s−1)[X³]_k) + θ18 F0(ã_x)δ_k0
//! ```
//!
//! **Deviation form and precision.** The RLS estimates δθ = θ − θ_nom, so it needs the
//! innovation `z − Φ θ_nom`. In the drive fundamental row the terms are of size ~1 and
//! cancel to ~1e-7 (the Coriolis term times 1 %, FINDINGS §4), so forming `z − Φθ_nom`
//! from separately filtered signals loses everything in `f32`. Here the filters are
//! linear, so the innovation is formed *before* filtering: the large terms are combined
//! at the signal level into `v0 = −ik ω′A − (k²ω² + θ12n)A − …` where the constant
//! `k²ω_ref² + θ12n` is precomputed in `f64`, the pump frequency enters only as the small
//! deviation `ω² − ω_ref²`, and what is filtered is already small. `F1` and `F2` outputs are
//! accurate by construction (see `svf`). The regressor columns `Φ` (multiplied only by
//! the small δθ) are filtered as they are.
//!
//! **A drifting coefficient.** The filter does not commute with a coefficient that moves:
//! for θ(t) = θ + θ′t, exactly, `H[θB] = θ(t − 2/w)·F0(B) + (2θ′/w²)·L[F1(B)]`
//! (`H = w²/(s + w)²`; its first-moment filter `−H′(s) = 2w²/(s + w)³` is
//! `(2/w)·H·(1 − s/(s + w))`; `L = w/(s + w)`, the filter's first stage). The first term
//! is why a drift's estimate lags by the filter's group delay 2/w (the estimator reads it
//! advanced, module `drift`); the second is a term proportional to the envelope's
//! derivative that no column carries, so a warm-up's θ22′ otherwise leaks into θ21, θ23
//! and θ24 (and the rate). `L` matters: the pump dither moves the envelopes at 5 Hz,
//! where the 10 Hz stage has a gain of 0.89 and a phase of −27°, and the phase leaks into
//! the other columns. The sense's fundamental rows subtract the term,
//! `g·L[F1(B1)]` with `g = 2θ22′/w²` and θ22′ the drift the estimator tracks
//! ([`RowBuilder::push_projected`]'s `g_sense`; `L` FOH-exact, [`PoleState`]). The drive's
//! θ12′ has the same term in the drive rows, and the DC and third-harmonic rows have
//! theirs; they are left out (the sense fundamental is the row the rate is read from, and
//! its θ22 column the large one; the drive's, measured, moves the 20 s warm-up's rate
//! error by −0.04 to +0.02 of its rms before the ramp: core/docs/design-notes.md).

use crate::complex::Cplx;
use crate::harmonics::{AxisProj, SynthTables, project};
use crate::real::Real;
use crate::svf::{CSvfState, PoleState, SvfCoeffs, SvfState};

/// Rows per axis per sample.
pub const NROWS: usize = 5;
/// Row names in order.
pub const ROW_NAMES: [&str; NROWS] = ["dc", "h1_re", "h1_im", "h3_re", "h3_im"];

/// The known (commanded or measured) signals after the replica low-pass, at one sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Known<T> {
    /// ω (pump half-frequency, non-dimensional).
    pub om: T,
    /// ω² − ω_ref².
    pub dom2: T,
    /// ω′ (per τ).
    pub omd: T,
    /// s − 1 (pump voltage scale deviation).
    pub ds: T,
    /// ã_x (non-dimensional acceleration).
    pub ax: T,
    /// ã_y.
    pub ay: T,
}

/// Lock-in outputs in L0 units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Envelopes<T> {
    /// X0 (DC level of the drive).
    pub x0: T,
    /// A1, A2, A3.
    pub a: [Cplx<T>; 3],
    /// Y0.
    pub y0: T,
    /// B1, B2, B3.
    pub b: [Cplx<T>; 3],
}

/// One sample's rows, unweighted and unscaled: `y[r] = z[r] − Φ[r]·θ_nom` and `Φ[r]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RowSet<T> {
    /// Drive regressors Φ1 (row r, column j).
    pub drive_phi: [[T; 8]; NROWS],
    /// Drive innovations about θ_nom.
    pub drive_y: [T; NROWS],
    /// Sense regressors Φ2.
    pub sense_phi: [[T; 6]; NROWS],
    /// Sense innovations about θ_nom.
    pub sense_y: [T; NROWS],
}

/// The nominal θ (the linearisation point) and the derived constants the rows need, in
/// `T`. State, not design: re-linearisation moves it.
#[derive(Clone, Copy, Debug, Default)]
pub struct NominalConsts<T> {
    th1: [T; 8],
    th2: [T; 6],
    /// k²ω_ref² + θ12n for k = 0, 1, 3.
    c12: [T; 3],
    /// k²ω_ref² + θ22n for k = 0, 1, 3.
    c22: [T; 3],
}

impl<T: Real> NominalConsts<T> {
    /// From the nominal θ (f64) and the reference ω.
    pub fn new(th1: &[f64; 8], th2: &[f64; 6], om_ref: f64) -> Self {
        let mut t1 = [T::ZERO; 8];
        let mut t2 = [T::ZERO; 6];
        for (d, s) in t1.iter_mut().zip(th1) {
            *d = T::from_f64(*s);
        }
        for (d, s) in t2.iter_mut().zip(th2) {
            *d = T::from_f64(*s);
        }
        let w2 = om_ref * om_ref;
        let ks = [0.0, 1.0, 9.0];
        let mut c12 = [T::ZERO; 3];
        let mut c22 = [T::ZERO; 3];
        for i in 0..3 {
            c12[i] = T::from_f64(ks[i] * w2 + th1[1]);
            c22[i] = T::from_f64(ks[i] * w2 + th2[1]);
        }
        NominalConsts {
            th1: t1,
            th2: t2,
            c12,
            c22,
        }
    }
}

#[derive(Clone, Copy, Debug, Default)]
struct HarmFilters<T> {
    a: CSvfState<T>,
    b: CSvfState<T>,
    oma: CSvfState<T>,
    omb: CSvfState<T>,
    p15: CSvfState<T>,
    p16: CSvfState<T>,
    p17: CSvfState<T>,
    p25: CSvfState<T>,
    vx: CSvfState<T>,
    vy: CSvfState<T>,
}

#[derive(Clone, Copy, Debug, Default)]
struct DcFilters<T> {
    x0: SvfState<T>,
    y0: SvfState<T>,
    p15: SvfState<T>,
    p16: SvfState<T>,
    p17: SvfState<T>,
    p25: SvfState<T>,
    ax: SvfState<T>,
    ay: SvfState<T>,
    vx: SvfState<T>,
    vy: SvfState<T>,
}

/// Unfiltered inputs of one harmonic's filters.
#[derive(Clone, Copy, Debug, Default)]
struct HarmInputs<T> {
    a: Cplx<T>,
    b: Cplx<T>,
    oma: Cplx<T>,
    omb: Cplx<T>,
    p15: Cplx<T>,
    p16: Cplx<T>,
    p17: Cplx<T>,
    p25: Cplx<T>,
    vx: Cplx<T>,
    vy: Cplx<T>,
}

#[derive(Clone, Copy, Debug, Default)]
struct DcInputs<T> {
    x0: T,
    y0: T,
    p15: T,
    p16: T,
    p17: T,
    p25: T,
    ax: T,
    ay: T,
    vx: T,
    vy: T,
}

/// The harmonic projections of one sample (both axes), shared by the rows and the fast
/// rate channel (which needs the sense cube's fundamental `[Y³]₁`).
#[derive(Clone, Copy, Debug, Default)]
pub struct Projections<T> {
    /// Drive axis.
    pub x: AxisProj<T>,
    /// Sense axis.
    pub y: AxisProj<T>,
}

impl<T: Real> Projections<T> {
    /// The projections of the envelopes `e`.
    #[inline(always)]
    pub fn of(design: &RowDesign<T>, e: &Envelopes<T>) -> Self {
        Projections {
            x: project(&design.tables, e.x0, &e.a, true),
            y: project(&design.tables, e.y0, &e.b, false),
        }
    }
}

/// The design of the row builder: the slow state-variable filter's coefficients and the
/// synthesis tables of the harmonic projections (built once; `Default` is the all-zero
/// placeholder of an estimator that is not designed yet).
#[derive(Clone, Copy, Debug, Default)]
pub struct RowDesign<T> {
    svf: SvfCoeffs<T>,
    tables: SynthTables<T>,
    /// 1/w (τ): a column's move over the filter's delay 2/w, times this, is the
    /// coefficient `2θ′/w²` of its `F1` (module docs, "A drifting coefficient").
    pub inv_w: f64,
}

impl<T: Real> RowDesign<T> {
    /// For SVF corner `w` (rad/τ) and sample period `ts` (τ).
    #[inline(never)] // set-up only: its own frame (the chip's stack)
    pub fn new(w: f64, ts: f64) -> Self {
        RowDesign {
            svf: SvfCoeffs::new(w, ts),
            tables: SynthTables::new(),
            inv_w: 1.0 / w,
        }
    }
}

/// The state of the row builder: the state-variable filter bank and the linearisation
/// point (its design is a [`RowDesign`]). `Default`: not started, zero nominal.
#[derive(Clone, Copy, Debug, Default)]
pub struct RowBuilder<T> {
    nom: NominalConsts<T>,
    h: [HarmFilters<T>; 2],
    dc: DcFilters<T>,
    /// `L[F1(B1)]`, the sense drift's term (module docs, "A drifting coefficient").
    b1_drift: PoleState<T>,
    started: bool,
}

impl<T: Real> RowBuilder<T> {
    /// Filters that start at rest at the first sample, linearised about `nom`.
    pub fn new(nom: NominalConsts<T>) -> Self {
        RowBuilder {
            nom,
            h: [HarmFilters::default(); 2],
            dc: DcFilters::default(),
            b1_drift: PoleState::default(),
            started: false,
        }
    }

    /// Moves the linearisation point to a new nominal θ (e.g. the settled estimate), so
    /// that the combined signals stay small and the `f32` innovation keeps its precision.
    ///
    /// The combination filters hold the state of `v0 = … − Σ θn_j g_j` where `g_j` are
    /// the unfiltered column signals; the filters are linear and share their
    /// coefficients, so the new state is the old one minus `Σ Δθ_j · state(g_j)`, exactly
    /// in exact arithmetic. The regressor columns are unchanged.
    pub fn relinearize(&mut self, th1: &[f64; 8], th2: &[f64; 6], om_ref: f64) {
        self.relinearize_to(&NominalConsts::<T>::new(th1, th2, om_ref));
    }

    /// [`RowBuilder::relinearize`] to constants built beforehand (the estimator's spread
    /// re-linearisation builds them on an earlier tick).
    pub fn relinearize_to(&mut self, new: &NominalConsts<T>) {
        let mut d1 = [T::ZERO; 8];
        let mut d2 = [T::ZERO; 6];
        for j in 0..8 {
            d1[j] = new.th1[j] - self.nom.th1[j];
        }
        for j in 0..6 {
            d2[j] = new.th2[j] - self.nom.th2[j];
        }
        if self.started {
            for (hi, f) in self.h.iter_mut().enumerate() {
                let k = if hi == 0 { T::ONE } else { T::from_f64(3.0) };
                // the coefficient of A in v0 is −(k²ω_ref² + θ12n + k²δω²): use the
                // difference of the precomputed small constants, not of the rounded θ12n
                let dc12 = new.c12[hi + 1] - self.nom.c12[hi + 1];
                let dc22 = new.c22[hi + 1] - self.nom.c22[hi + 1];
                // ∂v0x/∂θ: θ11 → −ik ωA, θ12 → −A, θ13 → −B, θ14 → −ik ωB, θ15..17 → −P
                let neg = |v: T| Cplx::new(-v, T::ZERO);
                let negik = |v: T| Cplx::new(T::ZERO, -k * v);
                let (oma, omb, a, b, p15, p16, p17, p25) =
                    (f.oma, f.omb, f.a, f.b, f.p15, f.p16, f.p17, f.p25);
                f.vx.caxpy(negik(d1[0]), &oma);
                f.vx.caxpy(neg(dc12), &a);
                f.vx.caxpy(neg(d1[2]), &b);
                f.vx.caxpy(negik(d1[3]), &omb);
                f.vx.caxpy(neg(d1[4]), &p15);
                f.vx.caxpy(neg(d1[5]), &p16);
                f.vx.caxpy(neg(d1[6]), &p17);
                f.vy.caxpy(negik(d2[0]), &omb);
                f.vy.caxpy(neg(dc22), &b);
                f.vy.caxpy(neg(d2[2]), &a);
                f.vy.caxpy(negik(d2[3]), &oma);
                f.vy.caxpy(neg(d2[4]), &p25);
            }
            let d = &mut self.dc;
            let (x0, y0, p15, p16, p17, p25, ax, ay) =
                (d.x0, d.y0, d.p15, d.p16, d.p17, d.p25, d.ax, d.ay);
            d.vx.axpy(-d1[1], &x0);
            d.vx.axpy(-d1[2], &y0);
            d.vx.axpy(-d1[4], &p15);
            d.vx.axpy(-d1[5], &p16);
            d.vx.axpy(-d1[6], &p17);
            d.vx.axpy(-d1[7], &ax);
            d.vy.axpy(-d2[1], &y0);
            d.vy.axpy(-d2[2], &x0);
            d.vy.axpy(-d2[4], &p25);
            d.vy.axpy(-d2[5], &ay);
        }
        self.nom = *new;
    }

    /// Restarts the filters at the next sample (they start at rest at its values).
    pub fn restart(&mut self) {
        self.started = false;
    }

    fn harm_inputs(
        &self,
        k: usize,
        e: &Envelopes<T>,
        kn: &Known<T>,
        px: &AxisProj<T>,
        py: &AxisProj<T>,
    ) -> HarmInputs<T> {
        let n = &self.nom;
        // k = 1 → index 0 (A1), k = 3 → index 2 (A3)
        let (ai, ci, kk) = if k == 1 {
            (0, 1, T::ONE)
        } else {
            (2, 2, T::from_f64(3.0))
        };
        let k2 = kk * kk;
        let a = e.a[ai];
        let b = e.b[ai];
        let (p15, xc, x3c, p25) = if k == 1 {
            (px.cube.h1, px.lin_cos.h1, px.cube_cos.h1, py.cube.h1)
        } else {
            (px.cube.h3, px.lin_cos.h3, px.cube_cos.h3, py.cube.h3)
        };
        let ds = kn.ds;
        let p16 = xc + (xc + a).scale(ds);
        let p17 = x3c + (x3c + p15).scale(ds);
        let oma = a.scale(kn.om);
        let omb = b.scale(kn.om);
        // nominal combinations (the F0 part of z − Φθ_nom), small by construction
        let lin_x = n.c12[ci] + k2 * kn.dom2;
        let lin_y = n.c22[ci] + k2 * kn.dom2;
        let vx = -(a.scale(kk * kn.omd) + (oma.scale(n.th1[0]) + omb.scale(n.th1[3])).scale(kk))
            .mul_i()
            - a.scale(lin_x)
            - b.scale(n.th1[2])
            - p15.scale(n.th1[4])
            - p16.scale(n.th1[5])
            - p17.scale(n.th1[6]);
        let vy = -(b.scale(kk * kn.omd) + (omb.scale(n.th2[0]) + oma.scale(n.th2[3])).scale(kk))
            .mul_i()
            - b.scale(lin_y)
            - a.scale(n.th2[2])
            - p25.scale(n.th2[4]);
        HarmInputs {
            a,
            b,
            oma,
            omb,
            p15,
            p16,
            p17,
            p25,
            vx,
            vy,
        }
    }

    fn dc_inputs(
        &self,
        e: &Envelopes<T>,
        kn: &Known<T>,
        px: &AxisProj<T>,
        py: &AxisProj<T>,
    ) -> DcInputs<T> {
        let n = &self.nom;
        let ds = kn.ds;
        let p15 = px.cube.h0;
        let p16 = px.lin_cos.h0 + (px.lin_cos.h0 + e.x0) * ds;
        let p17 = px.cube_cos.h0 + (px.cube_cos.h0 + p15) * ds;
        let p25 = py.cube.h0;
        let vx = -(n.c12[0] * e.x0)
            - n.th1[2] * e.y0
            - n.th1[4] * p15
            - n.th1[5] * p16
            - n.th1[6] * p17
            - n.th1[7] * kn.ax;
        let vy = -(n.c22[0] * e.y0) - n.th2[2] * e.x0 - n.th2[4] * p25 - n.th2[5] * kn.ay;
        DcInputs {
            x0: e.x0,
            y0: e.y0,
            p15,
            p16,
            p17,
            p25,
            ax: kn.ax,
            ay: kn.ay,
            vx,
            vy,
        }
    }

    /// Feeds one sample; writes its rows into `rows` (every entry is overwritten, so
    /// the caller's buffer needs no clearing: no 320-byte zeroing and copy per tick).
    #[inline(never)]
    pub fn push(
        &mut self,
        design: &RowDesign<T>,
        e: &Envelopes<T>,
        kn: &Known<T>,
        rows: &mut RowSet<T>,
    ) {
        let p = Projections::of(design, e);
        self.push_projected(design, e, kn, &p, T::ZERO, rows);
    }

    /// [`RowBuilder::push`] with the projections already made (the estimator's tick:
    /// the fast rate channel needs the sense cube's fundamental too), and the sense's
    /// drift term `g_sense` = 2θ22′/w² (module docs, "A drifting coefficient"; 0: none).
    #[inline(always)]
    pub fn push_projected(
        &mut self,
        design: &RowDesign<T>,
        e: &Envelopes<T>,
        kn: &Known<T>,
        p: &Projections<T>,
        g_sense: T,
        rows: &mut RowSet<T>,
    ) {
        let (px, py) = (p.x, p.y);
        let hin = [
            self.harm_inputs(1, e, kn, &px, &py),
            self.harm_inputs(3, e, kn, &px, &py),
        ];
        let din = self.dc_inputs(e, kn, &px, &py);
        if !self.started {
            for (f, i) in self.h.iter_mut().zip(hin.iter()) {
                f.a = CSvfState::at_rest(i.a);
                f.b = CSvfState::at_rest(i.b);
                f.oma = CSvfState::at_rest(i.oma);
                f.omb = CSvfState::at_rest(i.omb);
                f.p15 = CSvfState::at_rest(i.p15);
                f.p16 = CSvfState::at_rest(i.p16);
                f.p17 = CSvfState::at_rest(i.p17);
                f.p25 = CSvfState::at_rest(i.p25);
                f.vx = CSvfState::at_rest(i.vx);
                f.vy = CSvfState::at_rest(i.vy);
            }
            let d = &mut self.dc;
            d.x0 = SvfState::at_rest(din.x0);
            d.y0 = SvfState::at_rest(din.y0);
            d.p15 = SvfState::at_rest(din.p15);
            d.p16 = SvfState::at_rest(din.p16);
            d.p17 = SvfState::at_rest(din.p17);
            d.p25 = SvfState::at_rest(din.p25);
            d.ax = SvfState::at_rest(din.ax);
            d.ay = SvfState::at_rest(din.ay);
            d.vx = SvfState::at_rest(din.vx);
            d.vy = SvfState::at_rest(din.vy);
            // at rest F1 = 0
            self.b1_drift = PoleState::default();
            self.started = true;
        }
        let c = design.svf;
        let n = self.nom;

        // ---- DC rows (row 0)
        {
            let d = &mut self.dc;
            let x0 = d.x0.update(&c, din.x0);
            let y0 = d.y0.update(&c, din.y0);
            let p15 = d.p15.update(&c, din.p15);
            let p16 = d.p16.update(&c, din.p16);
            let p17 = d.p17.update(&c, din.p17);
            let p25 = d.p25.update(&c, din.p25);
            let ax = d.ax.update(&c, din.ax);
            let ay = d.ay.update(&c, din.ay);
            let vx = d.vx.update(&c, din.vx);
            let vy = d.vy.update(&c, din.vy);
            rows.drive_phi[0] = [x0.f1, x0.f0, y0.f0, y0.f1, p15.f0, p16.f0, p17.f0, ax.f0];
            rows.drive_y[0] = x0.f2 - n.th1[0] * x0.f1 - n.th1[3] * y0.f1 + vx.f0;
            rows.sense_phi[0] = [y0.f1, y0.f0, x0.f0, x0.f1, p25.f0, ay.f0];
            rows.sense_y[0] = y0.f2 - n.th2[0] * y0.f1 - n.th2[3] * x0.f1 + vy.f0;
        }
        // ---- harmonic rows (1, 2: k = 1; 3, 4: k = 3)
        let mut b1_f1 = Cplx::ZERO;
        for hi in 0..2 {
            let kk = if hi == 0 { T::ONE } else { T::from_f64(3.0) };
            let f = &mut self.h[hi];
            let i = &hin[hi];
            let a = f.a.update(&c, i.a);
            let b = f.b.update(&c, i.b);
            if hi == 0 {
                b1_f1 = b.f1;
            }
            let oma = f.oma.update(&c, i.oma);
            let omb = f.omb.update(&c, i.omb);
            let p15 = f.p15.update(&c, i.p15);
            let p16 = f.p16.update(&c, i.p16);
            let p17 = f.p17.update(&c, i.p17);
            let p25 = f.p25.update(&c, i.p25);
            let vx = f.vx.update(&c, i.vx);
            let vy = f.vy.update(&c, i.vy);
            // columns (complex)
            let c11 = a.f1 + oma.f0.scale(kk).mul_i();
            let c14 = b.f1 + omb.f0.scale(kk).mul_i();
            let cx = [c11, a.f0, b.f0, c14, p15.f0, p16.f0, p17.f0, Cplx::ZERO];
            let zx =
                a.f2 + oma.f1.scale(kk + kk).mul_i() - a.f1.scale(n.th1[0]) - b.f1.scale(n.th1[3])
                    + vx.f0;
            let cy = [c14, b.f0, a.f0, c11, p25.f0, Cplx::ZERO];
            let zy =
                b.f2 + omb.f1.scale(kk + kk).mul_i() - b.f1.scale(n.th2[0]) - a.f1.scale(n.th2[3])
                    + vy.f0;
            let r = 1 + 2 * hi;
            for j in 0..8 {
                rows.drive_phi[r][j] = cx[j].re;
                rows.drive_phi[r + 1][j] = cx[j].im;
            }
            for j in 0..6 {
                rows.sense_phi[r][j] = cy[j].re;
                rows.sense_phi[r + 1][j] = cy[j].im;
            }
            rows.drive_y[r] = zx.re;
            rows.drive_y[r + 1] = zx.im;
            rows.sense_y[r] = zy.re;
            rows.sense_y[r + 1] = zy.im;
        }
        // the drifting θ22's term in the sense fundamental (module docs)
        let l = self.b1_drift.update(&c, b1_f1);
        rows.sense_y[1] -= g_sense * l.re;
        rows.sense_y[2] -= g_sense * l.im;
    }
}
