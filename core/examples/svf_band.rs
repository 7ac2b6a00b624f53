//! The fast rate channel's wide filter against the continuous filter it stands for.
//!
//! ```text
//! cargo run --release -p paragyro-core --example svf_band
//! ```
//!
//! For a sampled sinusoid at Ω, the FOH-exact discrete filter (`svf`) gives each output
//! `F_j` (j = 0, 1, 2: `w²D^j/(D + w)²`) as the continuous filter would times a ratio
//! `R_j(Ω)`; a relation between filtered signals (a row) holds as long as the ratios are
//! equal, whatever their common value. The ratios are printed raw and with the channel's
//! curvature correction (`rate.rs`: `F0 − e0·F2`, `F1 − e1·F2`, `g·F2`), for the
//! configuration's wide filter (`rate.svf_hz` at `fs_hz`), and `R1 − R0`: the row's fast
//! part balances `2iω·F1(B)` against the quadrature's `θ23·F0(A)`, so the ringing a pump
//! step leaves in the drive is misread in proportion to it (`F2` enters that balance Ω/2ω
//! times less). Then `F0`'s ratio with the band taps the channel applies
//! (`svf::band_taps`) and what they leave of `R1 − R0`. Prints Markdown.

use paragyro_core::Config;
use paragyro_core::svf::{BAND_TAPS, BAND_WT, band_taps, parabola_bias, sine_response};

type C = (f64, f64);

fn mul(a: C, b: C) -> C {
    (a.0 * b.0 - a.1 * b.1, a.0 * b.1 + a.1 * b.0)
}

fn div(a: C, b: C) -> C {
    let d = b.0 * b.0 + b.1 * b.1;
    ((a.0 * b.0 + a.1 * b.1) / d, (a.1 * b.0 - a.0 * b.1) / d)
}

fn fmt(c: C) -> String {
    format!("{:.4} {:+.4}i", c.0, c.1)
}

fn main() {
    let cfg = Config::table2();
    let omega0 = cfg.omega0_rad_s();
    let ts = omega0 / cfg.fs_hz;
    let w = 2.0 * std::f64::consts::PI * cfg.rate.svf_hz / omega0;
    let eps = parabola_bias::<f64>(w, ts);
    let g = 1.0 / (1.0 + eps[2]);
    let (e0, e1) = (eps[0] * g, eps[1] * g);
    println!(
        "# The wide filter ({} Hz at {} Hz, wT = {:.3}) against the continuous filter\n",
        cfg.rate.svf_hz,
        cfg.fs_hz,
        w * ts
    );
    println!(
        "| Hz | R0 | R1 | R2 | corrected R0 | corrected R1 | corrected R2 | \\|R1 − R0\\| corrected |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for hz in [5.0, 10.0, 30.0, 60.0, 80.0, 100.0, 150.0] {
        let om = 2.0 * std::f64::consts::PI * hz / omega0;
        let d = sine_response(w, ts, om * ts);
        let s = (0.0, om);
        let h0 = div((w * w, 0.0), mul((w, om), (w, om)));
        let h = [h0, mul(h0, s), mul(mul(h0, s), s)];
        let raw: Vec<C> = (0..3).map(|j| div(d[j], h[j])).collect();
        let corr = [
            (d[0].0 - e0 * d[2].0, d[0].1 - e0 * d[2].1),
            (d[1].0 - e1 * d[2].0, d[1].1 - e1 * d[2].1),
            (g * d[2].0, g * d[2].1),
        ];
        let r: Vec<C> = (0..3).map(|j| div(corr[j], h[j])).collect();
        let gap = (r[1].0 - r[0].0).hypot(r[1].1 - r[0].1);
        println!(
            "| {hz} | {} | {} | {} | {} | {} | {} | {gap:.4} |",
            fmt(raw[0]),
            fmt(raw[1]),
            fmt(raw[2]),
            fmt(r[0]),
            fmt(r[1]),
            fmt(r[2])
        );
    }
    // the shipped band taps (`svf::band_taps`) when the design is the default one
    let [a, b] = if (w * ts - BAND_WT).abs() < 1e-9 {
        BAND_TAPS
    } else {
        band_taps(w * ts)
    };
    println!(
        "\nWith the band taps (`svf::band_taps`: a = {a:.4}, b = {b:.4} in units of e0), F0 − (1 + a)·e0·F2[k] − b·e0·(F2[k] − F2[k−1]):\n"
    );
    println!("| Hz | corrected R0 with the taps | \\|R1 − R0\\| with the taps |");
    println!("|---|---|---|");
    for hz in [5.0, 10.0, 30.0, 60.0, 80.0, 100.0, 150.0] {
        let om = 2.0 * std::f64::consts::PI * hz / omega0;
        let x = om * ts;
        let d = sine_response(w, ts, x);
        let s = (0.0, om);
        let h0 = div((w * w, 0.0), mul((w, om), (w, om)));
        let h1 = mul(h0, s);
        let lagged = mul(d[2], (x.cos(), -x.sin()));
        let f0 = (
            d[0].0 - (1.0 + a) * e0 * d[2].0 - b * e0 * (d[2].0 - lagged.0),
            d[0].1 - (1.0 + a) * e0 * d[2].1 - b * e0 * (d[2].1 - lagged.1),
        );
        let r0 = div(f0, h0);
        let r1 = div((d[1].0 - e1 * d[2].0, d[1].1 - e1 * d[2].1), h1);
        println!(
            "| {hz} | {} | {:.4} |",
            fmt(r0),
            (r1.0 - r0.0).hypot(r1.1 - r0.1)
        );
    }
}
