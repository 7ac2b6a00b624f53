//! The lock-in front end against the header: DC gain 1, −3 dB at `lockin_lpf_hz` for the
//! header's order, and the noise at the stated density. Driven by synthetic pick-off
//! signals through the same integration path as a record ([`run`]).

use paragyro_refsim::plant::{Inputs, NQ};
use paragyro_refsim::protocol::Protocol;
use paragyro_refsim::sim::{FrontEnd, Source, run};

/// A pick-off signal: x reads `dc` + `amp`·cos(ψ + 2π·f·t) (the reference's 1st harmonic
/// offset by f), y reads nothing. No states.
struct Tone {
    dc: f64,
    amp: f64,
    f_hz: f64,
}

impl Source for Tone {
    fn rhs(&self, _t: f64, _q: &[f64; NQ], _u: &Inputs) -> [f64; NQ] {
        [0.0; NQ]
    }
    fn measure(&self, t: f64, _q: &[f64; NQ], _u: &Inputs, c1: f64, s1: f64) -> [f64; 2] {
        let (s, c) = (std::f64::consts::TAU * self.f_hz * t).sin_cos();
        [self.dc + self.amp * (c1 * c - s1 * s), 0.0]
    }
}

fn front_end(order: usize, hz: f64) -> FrontEnd {
    FrontEnd {
        lpf_order: order,
        lpf_hz: hz,
        noise_pm_rthz: 0.0,
        control_lockin: true,
        rtol: 1e-8,
        ..FrontEnd::default()
    }
}

/// |A1| over the last 0.1 s of a 0.4 s run of the tone (µm), and the DC channel's last value.
fn response(order: usize, hz: f64, f_hz: f64) -> (f64, f64) {
    let proto = Protocol::plain(0.4, 21_884.0, 0.0, [0.0; 2]);
    let tone = Tone {
        dc: 0.5e-6,
        amp: 1e-6,
        f_hz,
    };
    let sim = run(&tone, [0.0; NQ], &proto, &front_end(order, hz)).unwrap();
    let tail = &sim.rows[sim.rows.len() - 50..];
    let a1 = tail
        .iter()
        .map(|r| r.lockin_um[1].hypot(r.lockin_um[2]))
        .fold(0.0f64, f64::max);
    (a1, sim.rows.last().unwrap().lockin_um[0])
}

/// DC gain 1 on the DC channel and on the 1st harmonic (a tone at the reference), −3 dB
/// (1/√2) at the cut-off, for the default 4th order at 150 Hz and for other headers.
#[test]
fn dc_gain_and_cutoff_match_the_header() {
    for (order, hz) in [(4, 150.0), (2, 100.0), (6, 80.0)] {
        // what the filter lets through of the carrier (≈ 10.9 kHz) is real: the bound
        let ripple = 2.0 * (hz / 10_900.0f64).powi(order as i32) + 2e-6;
        let (a_dc, x0) = response(order, hz, 0.0);
        assert!((x0 - 0.5).abs() < ripple, "order {order}: DC channel {x0}");
        assert!(
            (a_dc - 1.0).abs() < ripple,
            "order {order}: |A1| at DC {a_dc}"
        );
        let (a_fc, _) = response(order, hz, hz);
        let want = std::f64::consts::FRAC_1_SQRT_2;
        assert!(
            (a_fc - want).abs() < ripple + 1e-4,
            "order {order}: |A1| at fc {a_fc}"
        );
        // an octave above: the Butterworth roll-off of that order
        let (a_2fc, _) = response(order, hz, 2.0 * hz);
        let want = 1.0 / (1.0 + 4f64.powi(order as i32)).sqrt();
        assert!(
            (a_2fc - want).abs() < ripple + 1e-4,
            "order {order}: |A1| at 2fc {a_2fc}"
        );
    }
}

/// The noise: with no signal, the channels' spread is the density through the filter:
/// σ² = D²/2 · 2fc·(π/2n)/sin(π/2n) on a DC channel, twice that on each harmonic's re/im.
#[test]
fn noise_has_the_stated_density() {
    let proto = Protocol::plain(4.0, 21_884.0, 0.0, [0.0; 2]);
    let fe = FrontEnd {
        noise_pm_rthz: 1.0,
        seed: 11,
        ..front_end(4, 150.0)
    };
    let quiet = Tone {
        dc: 0.0,
        amp: 0.0,
        f_hz: 0.0,
    };
    let sim = run(&quiet, [0.0; NQ], &proto, &fe).unwrap();
    let x = std::f64::consts::PI / 8.0;
    let enbw = 2.0 * 150.0 * x / x.sin();
    let d_um = 1e-6;
    for (c, want_var) in [(0, 0.5), (1, 1.0), (2, 1.0), (7, 0.5), (12, 1.0)] {
        let v: Vec<f64> = sim.rows[100..].iter().map(|r| r.lockin_um[c]).collect();
        let var = v.iter().map(|a| a * a).sum::<f64>() / v.len() as f64;
        let want = want_var * d_um * d_um * enbw;
        // 1900 samples, correlated over ~2 samples: ±10 % is > 3σ
        assert!(
            (var / want - 1.0).abs() < 0.1,
            "channel {c}: {var:.3e} vs {want:.3e}"
        );
    }
}
