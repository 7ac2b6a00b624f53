//! The plant is the project's physics: a noise-free record of the project's simulator and
//! this generator's record of the same device with the same inputs (its pump frequency,
//! pump scale and accelerations replayed row by row) agree.

mod common;

use paragyro_refsim::device::DeviceDraw;
use paragyro_refsim::effects::EffectSizes;
use paragyro_refsim::protocol::{Protocol, RateSine};
use paragyro_refsim::sim::{FrontEnd, simulate};
use paragyro_simulator::lockin::LockinExt;
use paragyro_simulator::scenario::{EventKind, EventSpec, Scenario};

/// The largest channel difference, µm, over rows after `skip`, and the largest |channel|.
fn compare(duration_s: f64, skip: usize, rtol: f64) -> (f64, f64, [f64; 14]) {
    compare_spp(duration_s, skip, rtol, 128)
}

fn compare_spp(duration_s: f64, skip: usize, rtol: f64, spp: usize) -> (f64, f64, [f64; 14]) {
    compare_with(
        Scenario::load("characterise").unwrap(),
        None,
        duration_s,
        skip,
        rtol,
        spp,
    )
}

/// The comparison on `sc` (its plant at rest, its rate plus `sine`).
fn compare_with(
    mut sc: Scenario,
    sine: Option<RateSine>,
    duration_s: f64,
    skip: usize,
    rtol: f64,
    spp: usize,
) -> (f64, f64, [f64; 14]) {
    sc.sim.steps_per_period = spp;
    sc.duration_s = duration_s;
    sc.sim.noise_pm_rthz = 0.0;
    let (rec, _) = paragyro_simulator::record::simulate_record(&sc, Some(1)).unwrap();
    let table = common::inputs_of(&rec);
    let dev = DeviceDraw::nominal(sc.plant.rate_dps);
    let mut proto = Protocol::plain(
        duration_s,
        table.pump_hz[0],
        sc.plant.rate_dps,
        [sc.plant.accel_x_mps2, sc.plant.accel_y_mps2],
    );
    proto.table = Some(table);
    proto.rate_sine = sine;
    let fe = FrontEnd {
        noise_pm_rthz: 0.0,
        rtol,
        x0_m: sc.plant.initial_x_um * 1e-6,
        ..FrontEnd::default()
    };
    let mine = simulate(&dev.si(), &EffectSizes::default(), &proto, &fe).unwrap();
    assert_eq!(mine.rows.len(), rec.rows.len());
    let mut dmax = 0.0f64;
    let mut amax = 0.0f64;
    let mut per = [0.0f64; 14];
    for (a, b) in mine.rows.iter().zip(&rec.rows).skip(skip) {
        let cb = b.lockin.to_channels();
        for c in 0..14 {
            let d = (a.lockin_um[c] - cb[c]).abs();
            per[c] = per[c].max(d);
            dmax = dmax.max(d);
            amax = amax.max(cb[c].abs());
        }
    }
    (dmax, amax, per)
}

/// 1.5 s of `characterise` (the drive builds up from 10 nm to its working amplitude of
/// ~2 µm and the dither starts at 1 s). With the simulator on a 256-step grid every channel
/// is within 1e-5 µm of its record (measured 2.9e-6 µm, 1.3e-6 relative; one 500 Hz
/// sample's noise at 1 pm/√Hz is ~1.2e-5 µm on a DC channel and ~1.7e-5 µm on a
/// harmonic); on its default 128-step grid within 1e-4 µm (measured 4.3e-5 µm). The
/// difference is the simulator's RK4 dispersion: it falls ~16× (h⁴) from 128 to 256 steps
/// (`convergence_scan`).
#[test]
fn a_clean_record_is_the_simulators() {
    let (dmax, amax, per) = compare_spp(1.5, 0, 1e-9, 256);
    eprintln!("256 steps: largest difference {dmax:.3e} µm of {amax:.3} µm; per channel {per:?}");
    assert!(amax > 1.5, "the drive did not build up: {amax}");
    assert!(dmax < 1e-5, "{dmax:.3e} µm");
    let (dmax, _, _) = compare(1.5, 0, 1e-9);
    eprintln!("128 steps: largest difference {dmax:.3e} µm");
    assert!(dmax < 1e-4, "{dmax:.3e} µm");
}

/// A moving rate (Ω and Ω̇ in every rate term): `characterise` with a sine of ±250 °/s at
/// 1 Hz on its 150 °/s (the rate goes through zero to −100 °/s, as a rate table reversing;
/// Ω̇ up to 1571 °/s²), the simulator's event `rate_sine` (θ held at each interval's
/// midpoint) against this generator's continuous Ω(t), on the simulator's 256-step grid.
#[test]
fn a_moving_rate_is_the_simulators() {
    let mut sc = Scenario::load("characterise").unwrap();
    let kind = EventKind::RateSine {
        amplitude_dps: 250.0,
        freq_hz: 1.0,
        duration_s: 10.0,
    };
    sc.events.insert(0, EventSpec { t_s: 0.0, kind });
    let sine = RateSine {
        t_s: 0.0,
        amplitude_dps: 250.0,
        freq_hz: 1.0,
    };
    let (dmax, amax, _) = compare_with(sc.clone(), Some(sine), 1.5, 0, 1e-9, 256);
    eprintln!("rate sine: largest difference {dmax:.3e} µm of {amax:.3} µm");
    // the same records without the sine on this side differ by the Coriolis response
    let (moved, _, _) = compare_with(sc, None, 1.5, 0, 1e-9, 256);
    eprintln!("without the sine here: {moved:.3e} µm");
    assert!(moved > 0.1, "{moved}");
    assert!(dmax < 2e-5, "{dmax:.3e} µm");
}

/// The numbers of the README: the difference against the simulator's grid and this
/// generator's tolerance (`cargo test -p paragyro-refsim --test against_simulator --
/// --ignored --nocapture`).
#[test]
#[ignore]
fn convergence_scan() {
    for spp in [64, 128, 256, 512] {
        let (dmax, amax, _) = compare_spp(1.5, 0, 1e-10, spp);
        eprintln!("simulator {spp} steps/period: {dmax:.3e} µm of {amax:.3} µm");
    }
    for rtol in [1e-8, 1e-9, 1e-10, 1e-11] {
        let t = std::time::Instant::now();
        let (dmax, _, _) = compare(1.5, 0, rtol);
        eprintln!(
            "refsim rtol {rtol:e}: {dmax:.3e} µm ({:.2} s with the simulator)",
            t.elapsed().as_secs_f64()
        );
    }
}
