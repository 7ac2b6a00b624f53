//! The parameter face (issue 11's acceptance cases): devices that are not the model,
//! diagnosed from their record alone against Table 2. A device whose parameters depart by
//! an ordinary tolerance reads `none`, with the deviations found within 2σ; an
//! electrostatic softening is named on a toleranced device when the record carries the
//! excitation that separates it (the pump-amplitude steps of `characterise`, its
//! electrodes carrying the pump), and reported as coherent with tolerance when it does not.

use paragyro_diagnose::blind::device::DeviceDraw;
use paragyro_diagnose::blind::outside::slowest_path_record;
use paragyro_diagnose::diagnose::calibrate::ParamDeviation;
use paragyro_diagnose::diagnose::{
    CALIBRATION_RESIMULATIONS, Options, Report, SHARE_MIN, T_SIG, diagnose,
};
use paragyro_simulator::record::{RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;
use rand::SeedableRng;

fn diagnosed(sc: &Scenario, effects: &[&str], seed: u64) -> Report {
    diagnosed_with(sc, effects, seed, &Options::default())
}

fn diagnosed_with(sc: &Scenario, effects: &[&str], seed: u64, o: &Options) -> Report {
    let opts = RecordOptions {
        seed: Some(seed),
        effects: effects.iter().map(|e| e.parse().unwrap()).collect(),
        rate_table: true,
        temp: Some((25.0, 4.0)),
    };
    let (rec, _truth) = simulate_record_with(sc, &opts, &mut |_| {}).unwrap();
    diagnose(&rec, o).unwrap().report
}

fn param<'a>(r: &'a Report, name: &str) -> &'a ParamDeviation {
    r.parameter_face.parameter(name).unwrap()
}

/// The calibrated value within `k`σ of `truth`.
fn within(r: &Report, name: &str, truth: f64, k: f64) {
    let p = param(r, name);
    let z = (p.device - truth) / p.sigma;
    println!(
        "{name}: {:.9e} ± {:.2e} (truth {truth:.9e}, {z:+.2}σ)",
        p.device, p.sigma
    );
    assert!(
        z.abs() <= k,
        "{name}: {} ± {} vs {truth}",
        p.device,
        p.sigma
    );
}

/// ωy² = 1.0275 instead of 1.0265 (+0.1 %, the pump re-centred on it): `none`, with
/// ωy² found within 2σ and flagged as the one significant deviation.
#[test]
fn wy2_tolerance_reads_none_with_its_deviation() {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.plant.wy2 = 1.0275;
    sc.estimator.pump_centre_hz = Some(2.0 * sc.plant.wy2.sqrt() * sc.sim.f0_hz);
    let r = diagnosed(&sc, &[], 21);
    assert_eq!(r.verdict.to_string(), "none", "{:?}", r.ranking);
    within(&r, "wy2", 1.0275, 2.0);
    assert!(param(&r, "wy2").t > 100.0);
    // nothing else moves
    for p in &r.parameter_face.parameters {
        if p.name != "wy2" {
            assert!(p.t.abs() < 4.0, "{p:?}");
        }
    }
    assert!(r.residual_over_noise < paragyro_diagnose::diagnose::NONE_NOISE_MAX);
    // the rate-table face names what else moves (θ14 − θ24) and what would separate it
    let h = r
        .parameter_face
        .hypotheses
        .iter()
        .find(|h| h.name == "anisodamping")
        .unwrap();
    assert!(
        h.detail.contains("pick-off") && h.detail.contains("electrical test signal"),
        "{}",
        h.detail
    );
}

/// μx = μy = 1.05e-3 (+5 %): `none`, both found within 2σ.
#[test]
fn damping_tolerance_reads_none_with_its_deviation() {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.plant.mu_x = 1.05e-3;
    sc.plant.mu_y = 1.05e-3;
    let r = diagnosed(&sc, &[], 22);
    assert_eq!(r.verdict.to_string(), "none", "{:?}", r.ranking);
    within(&r, "mu_x", 1.05e-3, 2.0);
    within(&r, "mu_y", 1.05e-3, 2.0);
}

/// A device with every parameter off by its tolerance, its own rate, accelerations and
/// noise (1.48 pm/√Hz), and an electrostatic softening whose electrodes carry the pump:
/// the `characterise` pump-amplitude steps move ωy² with s, which no tolerance does, so it
/// is named, with its size; the record's noise is estimated from the record.
#[test]
fn electrostatic_softening_is_named_on_a_toleranced_device() {
    let sc0 = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(2);
    let dev = DeviceDraw::draw(&mut rng);
    let sc = dev.apply(&sc0);
    // (noise seed 21: named, 9.36e-7 ± 2.3e-8; on noise seed 23 the linear test leaves it
    // `unknown` and the re-simulation confirms it: the test below)
    let r = diagnosed(&sc, &["electrostatic_softening=1e-6@1"], 21);
    assert_eq!(
        r.verdict.to_string(),
        "electrostatic_softening",
        "{:?}",
        r.ranking
    );
    let c = &r.ranking[0];
    let (size, sigma) = (c.size.unwrap(), c.size_sigma.unwrap());
    assert!((size - 1e-6).abs() < 0.1e-6, "{size} ± {sigma}");
    // its coherent alternatives are listed with the excitation that separates them
    println!("coherent with {:?}", c.coherent_with);
    let nu2 = r.parameter_face.noise_energy_ratio;
    let truth = dev.noise_pm_rthz.powi(2);
    assert!((nu2 / truth - 1.0).abs() < 0.15, "noise {nu2} vs {truth}");
    // the device's tolerances are found (ωx² −0.083 %, αx −3.3 %)
    let phys = dev.physical(&sc0);
    within(&r, "wx2", phys.wx2, 3.0);
    within(&r, "alpha_x", phys.alpha_x, 3.0);
}

/// The same softening from a fixed bias is a tolerance of ωy² and αy to this record:
/// `none`, and the parameter face says what would separate it (a bias step).
#[test]
fn a_fixed_bias_softening_is_coherent_with_tolerance() {
    let sc0 = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(3);
    let sc = DeviceDraw::draw(&mut rng).apply(&sc0);
    let r = diagnosed(&sc, &["electrostatic_softening=1e-6"], 24);
    assert_eq!(r.verdict.to_string(), "none", "{:?}", r.ranking);
    let h = r
        .parameter_face
        .hypotheses
        .iter()
        .find(|h| h.name == "electrostatic_softening")
        .unwrap();
    assert!(h.detail.contains("bias step"), "{}", h.detail);
    assert_ne!(h.status, "named");
}

/// The re-simulation's numerics (64 RK4 steps per period, pre-warped) against a 4× finer
/// reference of itself (256) on a record's own inputs, for the two targets of its
/// pre-warp: the simulated record's own 128-step grid (the header names it) and, with
/// the header's grid removed, the exact flow a device follows. Raw, every row within 0.1×
/// its noise; what the calibration would absorb leaves at most 1e-3× and moves ωy² by at
/// most 3e-9 relative (its σ on a 20 s record ~1e-8). The shifts are printed.
#[test]
fn simulator_numerics_are_below_a_tenth_of_the_noise() {
    let sc = Scenario::load("characterise").unwrap();
    let opts = RecordOptions {
        seed: Some(25),
        rate_table: true,
        temp: Some((25.0, 4.0)),
        ..RecordOptions::default()
    };
    let (rec, _) = simulate_record_with(&sc, &opts, &mut |_| {}).unwrap();
    let mut device = rec.clone();
    device
        .header
        .extra
        .retain(|(k, _)| !k.starts_with("simulator_"));
    for (target, rec) in [("the record's grid", &rec), ("the exact flow", &device)] {
        let g = paragyro_diagnose::diagnose::numerics::numerics_gap(
            rec,
            &paragyro_diagnose::diagnose::Model::table2(),
            Options::default().steps_per_period,
        )
        .unwrap();
        println!("towards {target}:");
        for ((row, e), (_, ea)) in g.per_row.iter().zip(&g.absorbed_per_row) {
            println!("  {row:<22} raw {e:.3e}, after the calibration {ea:.3e} of the noise");
        }
        for (name, r) in &g.absorbed_relative {
            println!("  {name:<8} absorbed {r:+.3e}");
        }
        assert!(g.max_over_noise <= 0.1, "{target}: {g:?}");
        assert!(g.absorbed_max_over_noise <= 1e-3, "{target}: {g:?}");
        let wy2 = g
            .absorbed_relative
            .iter()
            .find(|(n, _)| n == "wy2")
            .unwrap()
            .1;
        assert!(wy2.abs() <= 3e-9, "{target}: ωy² absorbs {wy2:e}");
    }
}

/// A toleranced device with the softening driven by the pump on noise seed 28: the linear
/// test says `unknown`; re-simulated with the softening, the record is at its noise
/// (1.08 ×) and the softening is the verdict. (Noise seed 23 was this case while the
/// `none` gate judged every record against one averaged noise profile: the linear column
/// left 5.8 % of the gap above that level unexplained. Against the record's own noise per
/// row the linear test names it on seeds 23–34 but 28.)
#[test]
fn a_softening_the_linear_test_leaves_unknown_is_confirmed_by_resimulation() {
    let sc0 = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(2);
    let sc = DeviceDraw::draw(&mut rng).apply(&sc0);
    let r = diagnosed(&sc, &["electrostatic_softening=1e-6@1"], 28);
    assert_eq!(r.verdict.to_string(), "electrostatic_softening");
    // the confirmation ran only because the linear test left it `unknown`
    let c = r.confirmation.last().expect("re-simulated");
    assert!(
        c.confirmed && c.effect.starts_with("electrostatic_softening"),
        "{c:?}"
    );
    assert!(c.residual_over_noise < 1.1, "{c:?}");
}

/// A large force leak (7e-4, 70× its detection limit) on a toleranced device whose drive
/// collapses and grows back under the pump's steps: with the re-simulation on the record's
/// branch after each collapse (`resim::on_record_branch`) the linear test names it at its
/// size, without a re-simulation of the effect. (With the re-simulation's regrowths on
/// branches of their own it read `unknown` there, and the confirmation named it.)
#[test]
fn a_large_force_leak_is_named_at_its_size() {
    let sc0 = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(300);
    let sc = DeviceDraw::draw(&mut rng).apply(&sc0);
    let r = diagnosed(&sc, &["force_leak=7e-4"], 21);
    assert_eq!(r.verdict.to_string(), "force_leak", "{:?}", r.confirmation);
    assert!(r.confirmation.is_empty(), "{:?}", r.confirmation);
    let size = r
        .ranking
        .iter()
        .find(|c| c.effect.to_string() == "force_leak")
        .and_then(|c| c.size)
        .unwrap();
    assert!((size - 7e-4).abs() < 0.05 * 7e-4, "{size}");
}

/// A simulated record names its integrator's grid (`simulator_omega_max`) and the
/// re-simulation takes it, so RK4's dispersion (ω² 8.3e-8 low at 128 steps per period)
/// cancels. With the diagnosis's own grid (a 1 % margin on the record's pump against the
/// record's 3 %), ωy² came out +0.006–0.009 ppm on clean devices at 0.1 pm/√Hz, a mean z
/// of +11 (`examples/clean 200 8` with `NOISE_PM=0.1 TEMP_RISE_K=0 ACCEL0=1`); this
/// device read +9.3σ.
#[test]
fn a_simulated_records_own_integrator_grid_leaves_no_wy2_bias() {
    let sc = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(200);
    let mut dev = DeviceDraw::draw(&mut rng);
    dev.noise_pm_rthz = 0.1;
    dev.accel_mps2 = [0.0; 2];
    let opts = RecordOptions {
        seed: Some(1200),
        rate_table: true,
        temp: Some((25.0, 0.0)),
        ..RecordOptions::default()
    };
    let (rec, _) = simulate_record_with(&dev.apply(&sc), &opts, &mut |_| {}).unwrap();
    assert!(
        rec.header
            .extra_value(paragyro_simulator::record::SIM_OMEGA_MAX_KEY)
            .is_some(),
        "the simulated record names its grid"
    );
    let r = diagnose(&rec, &Options::default()).unwrap().report;
    let truth = dev.physical(&sc).wy2;
    within(&r, "wy2", truth, 3.0);
}

/// A clean toleranced device whose sense 1st-harmonic rows carry twice the average
/// device's noise (development device 315 of `examples/clean`: 1.72 and 1.69 × ν² against
/// 0.87 and 0.71 on average, which put it at 1.145 × one averaged noise level, over
/// `none`'s 1.1). Its own noise per row, the lock-in's noise carried through its rows,
/// follows what its record shows, and it reads `none`.
#[test]
fn a_device_whose_rows_carry_more_noise_reads_none() {
    let sc = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(315);
    let dev = DeviceDraw::draw(&mut rng);
    let opts = RecordOptions {
        seed: Some(1315),
        rate_table: true,
        temp: Some((25.0, 4.0)),
        ..RecordOptions::default()
    };
    let (rec, _) = simulate_record_with(&dev.apply(&sc), &opts, &mut |_| {}).unwrap();
    let r = diagnose(&rec, &Options::default()).unwrap().report;
    let nu2 = r.parameter_face.noise_energy_ratio;
    for row in [6, 7] {
        let seen = r.held_out_by_row[row].baseline / nu2;
        let own = r.noise_per_row[row];
        println!("row {row}: held-out {seen:.3} × ν², its own noise {own:.3}");
        assert!(
            seen > 1.5,
            "row {row}: {seen} (not the device this test is for)"
        );
        assert!(
            (own / seen - 1.0).abs() < 0.15,
            "row {row}: {own} vs {seen}"
        );
    }
    assert_eq!(
        r.verdict.to_string(),
        "none",
        "{:.3}",
        r.residual_over_noise
    );
    assert!(r.residual_over_noise <= 1.05, "{}", r.residual_over_noise);
}

/// A large thermal drift (−45 ppm/K over a 4 K rise, 45× its detection limit) on a
/// toleranced device: the record's estimator carries the drifting θ22's own row term
/// (core `rows`, "A drifting coefficient"), so the calibration's θ do not absorb part of
/// the drift, and the linear test names it at its size (−45.06 ppm/K, 99.96 % of the gap
/// closed) without a re-simulation, with the default budget and with three runs alike.
#[test]
fn a_large_thermal_drift_is_named_at_its_size_by_the_linear_test() {
    let sc0 = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(61);
    let sc = DeviceDraw::draw(&mut rng).apply(&sc0);
    let three = Options {
        confirm_runs: Some(3),
        ..Options::default()
    };
    for r in [
        diagnosed_with(&sc, &["thermal_drift=-45"], 61, &three),
        diagnosed(&sc, &["thermal_drift=-45"], 61),
    ] {
        assert_eq!(r.verdict.to_string(), "thermal_drift", "{:?}", r.ranking);
        assert!(r.confirmation.is_empty(), "{:?}", r.confirmation);
        let top = r.ranking.first().expect("a ranking");
        let size = top.size.expect("sized");
        assert!((size + 45.0).abs() < 0.01 * 45.0, "{size}");
        assert!(top.gap_closure > 0.99, "{}", top.gap_closure);
    }
}

/// The bench's slowest-path record (60 s, a force leak at 7e-4 and a Coulomb friction no
/// library effect explains) with the defaults: the calibration converges in its usual two
/// steps, the linear test leaves `unknown`, and the force leak and the pump-driven softening
/// go to the confirmation, one run each (the budget's two on a 60 s record: the first
/// candidate's steps stop for the second's run), neither passing: four whole-record runs
/// in all, and `unknown`. The force leak's run leaves 11 % of the gap above the noise,
/// 5.9× the noise: the friction's.
#[test]
fn the_slowest_path_records_two_candidates_take_the_budgets_two_runs() {
    let rec = slowest_path_record().unwrap();
    let r = diagnose(&rec, &Options::default()).unwrap().report;
    assert_eq!(r.verdict.to_string(), "unknown", "{:?}", r.confirmation);
    assert_eq!(
        r.parameter_face.resimulations,
        1 + CALIBRATION_RESIMULATIONS,
        "{:?}",
        r.limitations
    );
    let tested: Vec<&str> = r
        .confirmation
        .iter()
        .map(|c| c.effect.split('=').next().unwrap_or(""))
        .collect();
    assert_eq!(tested, ["force_leak", "electrostatic_softening"]);
    for c in &r.confirmation {
        println!("{} {:?} {:?}", c.effect, c.runs, c.stopped);
        assert!(!c.confirmed, "{c:?}");
        assert_eq!(c.runs.len(), 1, "{c:?}");
    }
    assert!(r.timing_s.contains_key("resimulate_to_confirm"));
}

/// A large geometric nonlinearity (−5e-6, 50× its detection limit) on a toleranced
/// device: its linear column about the calibration fits its size within 0.04 %
/// (|size|/σ ≈ 1 300) and, with the re-simulation on the record's branch after each of the
/// drive's collapses, closes the held-out gap: the linear test names the nonlinearity at
/// its size, without a re-simulation of the effect.
/// (With the re-simulation's regrowths on branches of their own its held-out closure was
/// negative, and the confirmation's second place named it.)
#[test]
fn a_large_geometric_nonlinearity_is_named_at_its_size() {
    let sc0 = Scenario::load("characterise").unwrap();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(300);
    let sc = DeviceDraw::draw(&mut rng).apply(&sc0);
    let r = diagnosed(&sc, &["geometric_nonlinearity=-5e-6"], 21);
    assert_eq!(r.verdict.to_string(), "geometric_nonlinearity");
    assert!(r.verdict.secondary().is_none(), "{:?}", r.verdict);
    assert!(r.confirmation.is_empty(), "{:?}", r.confirmation);
    let gn = r.ranking.first().unwrap();
    assert_eq!(gn.effect.to_string(), "geometric_nonlinearity");
    let (size, sd) = (gn.size.unwrap(), gn.size_sigma.unwrap());
    assert!(
        size.abs() / sd >= T_SIG && gn.gap_closure >= SHARE_MIN,
        "{gn:?}"
    );
    assert!((size + 5e-6).abs() < 0.01 * 5e-6, "{size}");
}

/// Two effects at once (issue 31): a thermal drift of −0.58 and a feedthrough of −2.7e-4
/// on a toleranced device through a 4 K ramp (record 41 of the project's blind draw, seed
/// 1818). The linear test leaves `unknown`; the thermal drift re-simulated alone leaves
/// 6.4 % of the gap above the noise, over the 5 % the rules allow. Fitted with the 14 θ on
/// the gap that run leaves, the feedthrough brings the pair through both rules at its true
/// size: the verdict names both, without another run of the record.
#[test]
fn a_second_effect_the_first_ones_run_leaves_is_named_with_it() {
    let sc = Scenario::load("characterise").unwrap();
    let d = paragyro_diagnose::blind::draw(100, 1818)
        .into_iter()
        .nth(41)
        .unwrap();
    let truth: Vec<String> = d.effects.iter().map(|e| e.effect.to_string()).collect();
    assert_eq!(truth, ["feedthrough", "thermal_drift"], "the draw moved");
    let dir = std::env::temp_dir().join(format!("paragyro-pair-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("rec.csv");
    d.write_record(&sc, &path).unwrap();
    let rec = paragyro_simulator::record::read_record(&path).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let r = diagnose(&rec, &Options::default()).unwrap().report;
    assert_eq!(
        r.verdict.to_string(),
        "thermal_drift",
        "{:?}",
        r.confirmation
    );
    let second = r.verdict.secondary().expect("a second effect");
    assert_eq!(second.effect.to_string(), "feedthrough");
    let c = &r.confirmation[0];
    // the run alone failed the rules; the pair passed them
    assert!(
        c.effect.starts_with("thermal_drift") && !c.confirmed,
        "{c:?}"
    );
    assert!(c.unexplained > 0.05, "{c:?}");
    let pair = c.with.as_ref().expect("a pair");
    assert!(pair.unexplained <= 0.05, "{pair:?}");
    let with: paragyro_simulator::effects::EffectSpec = pair.effect.parse().unwrap();
    let size = d.effects[0].size;
    assert!(
        (with.size - size).abs() < 0.1 * size.abs(),
        "{with} against {size}"
    );
}
