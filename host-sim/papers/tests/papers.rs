//! Reproductions of the source papers: the averaged slow flow of seed 000's gyro against
//! the full-rate plant (`averaged`), and seed 001's Figs 3–4 (`paper001`).

use paragyro_core::Cplx;
use paragyro_papers::averaged::{
    AveragedModel, SteadyState, full_sim_envelopes, hysteresis_intervals, nearest_stable,
    write_averaged_report,
};
use paragyro_papers::paper001::{
    self, Params, eq22, existence_scan, parabola_family, rk4_eq19, stable_spatial,
    stationary_points, write_paper001_report,
};

fn rel(a: f64, b: f64) -> f64 {
    (a / b - 1.0).abs()
}

/// Steady state of the averaged model vs the full-rate plant (RK4 of eq. 6 + lock-in, no
/// noise, 0.5 s from X(0) = 0.01) at ω = √1.0265 (Table 2), for ωy² = 1.0265 and 1.03:
/// |A|, |B| within 1 % (and the complex envelopes up to the ± symmetry). FINDINGS §1:
/// full-rate lock-in |A1| = 1.7528, |B1| = 1.4960; ωy² = 1.03: |B1| = 0.7852; HB |Y| 1.4982.
#[test]
fn averaged_model_matches_the_full_plant_within_1_percent() {
    let om = 1.0265f64.sqrt();
    let cases = [(1.0265, Some(1.7528), 1.4960), (1.03, None, 0.7852)];
    for (wy2, a_ref, b_ref) in cases {
        let m = AveragedModel::table2().with_wy2(wy2);
        let states = m.steady_states(om);
        let (fa, fb) = full_sim_envelopes(&m, om, 0.5).unwrap();
        let st = nearest_stable(&states, fa, fb).expect("a stable steady state");
        println!(
            "ωy² = {wy2}: averaged |A| {:.5} |B| {:.5}; full |A1| {:.5} |B1| {:.5}",
            st.a.abs(),
            st.b.abs(),
            fa.abs(),
            fb.abs()
        );
        assert!(
            rel(st.a.abs(), fa.abs()) < 0.01,
            "|A| {} vs {}",
            st.a.abs(),
            fa.abs()
        );
        assert!(
            rel(st.b.abs(), fb.abs()) < 0.01,
            "|B| {} vs {}",
            st.b.abs(),
            fb.abs()
        );
        let d = |x: Cplx<f64>, y: Cplx<f64>| (x - y).abs().min((x + y).abs());
        assert!(d(st.a, fa) < 0.01 * fa.abs(), "A {:?} vs {fa:?}", st.a);
        assert!(d(st.b, fb) < 0.01 * fb.abs(), "B {:?} vs {fb:?}", st.b);
        // the full-rate plant itself reproduces FINDINGS §1
        if let Some(a) = a_ref {
            assert!(rel(fa.abs(), a) < 2e-3, "{} vs {a}", fa.abs());
        }
        assert!(rel(fb.abs(), b_ref) < 2e-3, "{} vs {b_ref}", fb.abs());
        if wy2 == 1.0265 {
            assert!((st.b.abs() - 1.4982).abs() < 1e-3, "HB |Y| {}", st.b.abs());
        }
    }
}

/// The rest-state instability band of Table 2: averaged formula (1.01125, 1.03333) and
/// Floquet of the full linear system (1.0109, 1.0334), FINDINGS §1.
#[test]
fn rest_state_band_table2() {
    let m = AveragedModel::table2();
    let (lo, hi) = m.trivial_band().unwrap();
    assert!(
        (lo - 1.01125).abs() < 1e-5 && (hi - 1.03333).abs() < 1e-5,
        "{lo} {hi}"
    );
    let (fl, fh) = m.floquet_band(1.005, 1.040, 2.5e-4).unwrap();
    println!("band: formula ({lo:.6}, {hi:.6}), Floquet ({fl:.6}, {fh:.6})");
    assert!(
        (fl - 1.0109).abs() < 1e-4 && (fh - 1.0334).abs() < 1e-4,
        "{fl} {fh}"
    );
    assert!(!m.trivial(1.02).stable && m.trivial(1.005).stable && m.trivial(1.04).stable);
}

fn settle_from(m: &AveragedModel, om: f64, st: &SteadyState, kick: f64) -> [f64; 4] {
    let v = st.v();
    m.settle(
        om,
        [v[0] * (1.0 + kick), v[1], v[2], v[3] * (1.0 - kick)],
        4e5,
    )
}

/// Stability classification at known points, confirmed by integrating the slow flow: the
/// Table 2 operating state is stable (and returns after a kick); at ω = 1.03 (inside the
/// band, above the fold at 1.0154) there are two stable states and an unstable one
/// between them (a kicked start leaves it); outside the band the rest state is stable and
/// the small-amplitude branch is a saddle.
#[test]
fn stability_classification_of_known_points() {
    let m = AveragedModel::table2();
    let om = 1.0265f64.sqrt();
    let st = m.steady_states(om);
    assert_eq!(st.len(), 1, "{st:?}");
    let s = st[0];
    assert!(s.stable && (s.max_re + 4.88e-4).abs() < 1e-5, "{s:?}");
    let back = settle_from(&m, om, &s, 0.02);
    assert!(back.iter().zip(s.v()).all(|(x, y)| (x - y).abs() < 1e-6));

    let om = 1.03;
    let st = m.steady_states(om);
    let stable: Vec<_> = st.iter().filter(|s| s.stable).collect();
    let unstable: Vec<_> = st.iter().filter(|s| !s.stable).collect();
    println!(
        "ω = 1.03: {} stable, {} unstable",
        stable.len(),
        unstable.len()
    );
    assert_eq!(stable.len(), 2, "{st:?}");
    assert!(!unstable.is_empty());
    assert!(!m.trivial(om).stable);
    let u = unstable[0];
    assert!(u.max_re > 1e-5, "{u:?}");
    let (lo_b, hi_b) = (stable[0].b.abs(), stable[1].b.abs());
    assert!(
        u.b.abs() > lo_b && u.b.abs() < hi_b,
        "saddle between the two: {u:?}"
    );
    let away = settle_from(&m, om, u, 1e-3);
    let d = away
        .iter()
        .zip(u.v())
        .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
    assert!(d > 0.1, "the unstable state was kept: {d}");
    // ... and the state it falls into is one of the two stable ones
    let hit = stable.iter().any(|s| {
        let w = s.v();
        away.iter().zip(w).all(|(x, y)| (x - y).abs() < 1e-5)
            || away.iter().zip(w).all(|(x, y)| (x + y).abs() < 1e-5)
    });
    assert!(hit, "{away:?}");

    let om = 1.04;
    assert!(m.trivial(om).stable);
    let st = m.steady_states(om);
    assert!(
        st.iter().any(|s| !s.stable && s.a.abs() < 3.0),
        "saddle branch: {st:?}"
    );
    assert!(
        st.iter().any(|s| s.stable && s.b.abs() > 7.0),
        "upper branch: {st:?}"
    );
}

/// Quasi-static up- and down-sweeps from rest: the up-sweep starts the drive at the lower
/// band edge and stays on the upper branch to the end of the grid; the down-sweep from
/// rest stays at rest down to the upper band edge, lands on the low-|B| branch and jumps
/// up at its fold (1.0154), so the hysteresis interval is [fold, end of grid].
#[test]
fn sweep_hysteresis() {
    let m = AveragedModel::table2();
    let grid: Vec<f64> = (0..=80).map(|i| 1.008 + 5e-4 * i as f64).collect();
    let rev: Vec<f64> = grid.iter().rev().copied().collect();
    let seed = [0.01, 0.0, 0.0, 0.0];
    let up = m.sweep(&grid, seed);
    let down = m.sweep(&rev, seed);
    let at = |s: &[paragyro_papers::averaged::SweepPoint], w: f64| {
        *s.iter().find(|p| (p.omega - w).abs() < 1e-9).unwrap()
    };
    assert!(up.iter().all(|p| p.stable) && down.iter().all(|p| p.stable));
    assert!(at(&up, 1.010).abs_a < 1e-3 && at(&up, 1.012).abs_a > 0.5);
    assert!(at(&up, 1.048).abs_b > 8.0);
    assert!(at(&down, 1.036).abs_a < 1e-3 && at(&down, 1.030).abs_a > 4.0);
    assert!(at(&down, 1.030).abs_b < 0.5);
    let hy = hysteresis_intervals(&up, &down, 0.05);
    println!("hysteresis {hy:?}");
    assert_eq!(hy.len(), 1);
    assert!(
        (hy[0].0 - 1.0155).abs() < 1.1e-3 && (hy[0].1 - 1.048).abs() < 1e-9,
        "{hy:?}"
    );
    let jumps: Vec<f64> = down.iter().filter(|p| p.jump).map(|p| p.omega).collect();
    assert!(jumps.iter().any(|w| (w - 1.033).abs() < 6e-4), "{jumps:?}");
    assert!(
        jumps.iter().any(|w| (w - 1.0155).abs() < 1.1e-3),
        "{jumps:?}"
    );
}

/// Every stationary regime found for seed 001 satisfies eq. (22) to 1e-10.
#[test]
fn paper001_stationary_regimes_satisfy_eq22() {
    let variants = [
        Params::fig3(),
        Params::fig4(),
        Params {
            gamma: 0.05,
            v0: 0.1,
            ..Params::fig4()
        },
    ];
    for p in variants {
        for lam in [-0.3, 0.04, 0.3, 1.0] {
            let pts = stationary_points(&p, lam);
            assert!(!pts.is_empty());
            for s in &pts {
                let r = eq22(&p, lam, &s.s);
                assert!(r.iter().all(|x| x.abs() <= 1e-10), "{p:?} λ={lam}: {r:?}");
            }
        }
    }
    // Fig. 3 at λ = 1: the plane regime, two stable spatial pairs, unstable ones
    let pts = stationary_points(&Params::fig3(), 1.0);
    assert!(
        pts.iter()
            .any(|s| s.b < 1e-9 && (s.a - 0.025).abs() < 1e-12 && s.stable)
    );
    assert!(pts.iter().any(|s| s.stable && s.b > 1.0));
    assert!(pts.iter().any(|s| !s.stable));
}

/// Direct RK4 integration of eq. (19) at two detunings keeps the stable regimes of (22)
/// (mean A, B within 3 %), converges to one with damping, and leaves an unstable one.
#[test]
fn paper001_rk4_confirms_the_slow_flow() {
    let p = Params::fig4();
    for lam in [0.5, 1.0] {
        let st = stable_spatial(&p, lam).unwrap();
        let r = rk4_eq19(&p, lam, &st.s, &st.s, 30_000.0, 0.0);
        println!(
            "λ = {lam}: A {:.4} vs {:.4}, B {:.4} vs {:.4}, max dev {:.3}",
            r.mean_a, st.a, r.mean_b, st.b, r.max_dev
        );
        assert!(
            rel(r.mean_a, st.a) < 0.03 && rel(r.mean_b, st.b) < 0.03,
            "{r:?} vs {st:?}"
        );
        assert!(r.max_dev < 0.1, "{r:?}");
    }
    let pd = Params {
        gamma: 0.05,
        ..Params::fig4()
    };
    let st = stable_spatial(&pd, 1.0).unwrap();
    let r = rk4_eq19(
        &pd,
        1.0,
        &st.s.map(|x| 1.05 * x),
        &st.s,
        120_000.0,
        100_000.0,
    );
    assert!(
        rel(r.mean_a, st.a) < 0.02 && rel(r.mean_b, st.b) < 0.02 && r.window_dev < 0.02,
        "{r:?}"
    );
    let un = stationary_points(&p, 1.0)
        .into_iter()
        .filter(|s| !s.stable && s.b > 0.5)
        .max_by(|x, y| x.max_re.total_cmp(&y.max_re))
        .unwrap();
    let start = [un.s[0] * (1.0 + 1e-3), un.s[1], un.s[2], un.s[3]];
    let r = rk4_eq19(&p, 1.0, &start, &un.s, 30_000.0, 0.0);
    assert!(r.max_dev > 0.2, "unstable regime kept: {r:?}");
}

/// The paper's existence condition, for the free regimes (m0 = 0, v1 = 0.1): the
/// parabolas c·j·A² = 8λ − 4v1 exist only for 2λ > v1, those with +4v1 for 2λ > −v1;
/// every regime lies on one of them.
#[test]
fn paper001_existence_condition() {
    let v1 = 0.1;
    let rows = existence_scan(v1, &[-0.06, -0.04, 0.04, 0.06, 0.5]);
    for &(lam, minus, plus, other) in &rows {
        println!("λ = {lam}: minus {minus}, plus {plus}, other {other}");
        assert_eq!(other, 0);
        assert_eq!(minus > 0, 2.0 * lam > v1, "λ = {lam}");
        assert_eq!(plus > 0, 2.0 * lam > -v1, "λ = {lam}");
    }
    let p = Params {
        m0: 0.0,
        ..Params::fig4()
    };
    for s in stationary_points(&p, 0.5) {
        assert!(parabola_family(&p, &s, 1e-8).is_some(), "{s:?}");
    }
    // v0 ≠ 0 splits symmetric pairs into more distinct (A, B) branches
    let n0 = paper001::distinct_amplitudes(&stationary_points(&Params::fig3(), 0.5)).len();
    let n1 = paper001::distinct_amplitudes(&stationary_points(
        &Params {
            v0: 0.1,
            ..Params::fig3()
        },
        0.5,
    ))
    .len();
    assert!(n1 > n0, "{n0} {n1}");
}

/// Both report writers produce their files and the key numbers. With
/// `PARAGYRO_PAPERS_OUT=DIR` the outputs are written to DIR and kept.
#[test]
fn reports_are_written() {
    let keep = std::env::var_os("PARAGYRO_PAPERS_OUT").map(std::path::PathBuf::from);
    let dir = keep.clone().unwrap_or_else(|| {
        std::env::temp_dir().join(format!("paragyro-papers-{}", std::process::id()))
    });
    let a = write_averaged_report(&dir).unwrap();
    let p = write_paper001_report(&dir).unwrap();
    for f in [
        "averaged_sweep.png",
        "averaged.json",
        "paper001_fig3.png",
        "paper001_fig4.png",
        "paper001.json",
    ] {
        let md = std::fs::metadata(dir.join(f)).unwrap();
        assert!(md.len() > 1000, "{f}");
    }
    let band = a.band.hb_formula_omega;
    assert!((band[0] - 1.01125).abs() < 1e-5);
    assert!(!a.paper_20pct_claim.reproduced);
    let ratio = a.paper_20pct_claim.hb_ratio;
    assert!((ratio - 0.526).abs() < 0.005, "{ratio}");
    let sw = a.sweeps.iter().find(|s| s.wy2 == 1.0265).unwrap();
    let hy = &sw.hysteresis_intervals_omega;
    assert_eq!(hy.len(), 1);
    assert!(p.rk4_checks_pass);
    assert!(p.claims.family_of_parabolas.holds);
    assert_eq!(p.claims.doubled_detuning_exceeds_v1.holds, "partly");
    assert!(p.claims.v0_adds_a_branch.holds);
    if keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}
