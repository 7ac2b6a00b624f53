//! Tests of the scenario loader, its errors and the plant over time.

use super::*;

const FILE: &str = "host-sim/scenarios/x.toml";

fn load_err(text: &str) -> ScenarioError {
    match Scenario::from_toml_str(text, FILE) {
        Ok(_) => panic!("expected an error for:\n{text}"),
        Err(e) => e,
    }
}

/// Asserts the message starts with `file:line` and mentions every fragment.
fn assert_err(e: &ScenarioError, line: usize, fragments: &[&str]) {
    let msg = e.to_string();
    assert!(
        msg.starts_with(&format!("{FILE}:{line}:")),
        "wrong file/line (want {FILE}:{line}): {msg}"
    );
    assert_eq!(e.line, Some(line), "{msg}");
    for f in fragments {
        assert!(msg.contains(f), "'{f}' missing from: {msg}");
    }
}

const BASE: &str = "name = \"t\"\nduration_s = 4.0\n";

#[test]
fn minimal_file_gets_the_defaults() {
    let s = Scenario::from_toml_str(BASE, FILE).unwrap();
    assert_eq!(s.plant, PlantSpec::default());
    assert_eq!(s.sim, SimSpec::default());
    assert_eq!(s.estimator, EstimatorSpec::default());
    assert_eq!(s.seed, 1);
    assert_eq!(s.source, FILE);
    assert!((s.omega0_rad_s() - 2.618 / 3.8581e-5).abs() < 1e-9);
    let pc = 2.0 * 1.0265f64.sqrt() * DEFAULT_F0_HZ;
    assert!((s.pump_centre_hz() - pc).abs() < 1e-9);
    // Table 2 θ (FINDINGS §0: θ13 = −0.002, θ14 = −2.28e-5, θ24 = −1.77e-4).
    let at = s.plant_at(0.0);
    assert!((at.theta_drive[2] + 0.002).abs() < 1e-12);
    assert!((at.theta_drive[3] + 2.2838e-5).abs() < 1e-8);
    assert!((at.theta_sense[3] + 1.7716e-4).abs() < 1e-8);
    assert!((at.phys[10] - 3.8581e-5).abs() < 1e-9);
    assert!((at.accel_x - 0.0213).abs() < 1e-4);
    assert_eq!(at.rate_dps, 150.0);
    // phys ↔ θ consistency.
    let back = phys_from_theta(&at.theta_drive, &at.theta_sense);
    for (a, b) in back.iter().zip(at.phys) {
        assert!((a - b).abs() <= 1e-15 + 1e-12 * b.abs(), "{a} vs {b}");
    }
}

#[test]
fn syntax_error_names_file_line_column() {
    let e = load_err("name = \"t\"\nduration_s = 4.0\n[plant\nwy2 = 1.0\n");
    assert_eq!(e.kind, ScenarioErrorKind::Syntax);
    assert_err(&e, 3, &["syntax error"]);
    assert!(e.column.is_some());
}

#[test]
fn wrong_type_names_the_field() {
    let e = load_err(&format!("{BASE}[plant]\nmu_x = 1e-3\nwy2 = \"abc\"\n"));
    assert_eq!(e.kind, ScenarioErrorKind::Schema);
    assert_err(
        &e,
        5,
        &["field 'plant.wy2'", "expected a float", "found a string"],
    );
    let e = load_err(&format!("{BASE}[sim]\nsteps_per_period = 128.5\n"));
    assert_err(&e, 4, &["field 'sim.steps_per_period'", "integer"]);
    let e = load_err(&format!("{BASE}[estimator]\nretune = 1\n"));
    assert_err(&e, 4, &["field 'estimator.retune'", "boolean"]);
}

#[test]
fn unknown_key_is_named() {
    let e = load_err(&format!("{BASE}[plant]\nwy2 = 1.03\nwz2 = 1.0\n"));
    assert_err(&e, 5, &["plant.wz2", "unknown key 'wz2'", "wy2"]);
    let e = load_err(&format!("{BASE}colour = 3\n"));
    assert_err(&e, 3, &["unknown key 'colour'"]);
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"dither\"\nenabled = true\nspeed = 2\n"
    ));
    assert_err(
        &e,
        7,
        &["event #1 (kind \"dither\")", "unknown key 'speed'"],
    );
}

#[test]
fn missing_required_key() {
    let e = load_err("name = \"t\"\n[plant]\nwy2 = 1.0\n");
    assert!(e.to_string().contains("field 'duration_s'"), "{e}");
    assert!(e.to_string().contains("missing"), "{e}");
    let e = load_err(&format!("{BASE}[[measure]]\nname = \"a\"\nfrom_s = 1.0\n"));
    assert_err(&e, 3, &["measure #1 (\"a\"), field 'to_s'", "missing"]);
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nto = 1.0\n"
    ));
    assert_err(&e, 3, &["event #1 (kind \"ramp\")", "'param'", "missing"]);
}

#[test]
fn unknown_event_kind() {
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"dither\"\nenabled = true\n\n[[event]]\nt_s = 1.0\nkind = \"rampp\"\n"
    ));
    assert_err(
        &e,
        10,
        &[
            "event #2 (kind \"rampp\")",
            "field 'kind'",
            "unknown event kind 'rampp'",
            "scale_theta",
        ],
    );
}

#[test]
fn unknown_ramp_param() {
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"wz2\"\nto = 1.0\n"
    ));
    assert_err(
        &e,
        6,
        &[
            "event #1 (kind \"ramp\")",
            "field 'param'",
            "unknown param 'wz2'",
            "wy2",
            "rate_dps",
        ],
    );
}

#[test]
fn key_of_another_kind_is_rejected() {
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.0\nfactor = 2.0\n"
    ));
    assert_err(
        &e,
        8,
        &["event #1 (kind \"ramp\")", "'factor'", "does not apply"],
    );
}

#[test]
fn negative_duration() {
    let e = load_err("name = \"t\"\n\nduration_s = -1\n");
    assert_eq!(e.kind, ScenarioErrorKind::Invalid);
    assert_err(&e, 3, &["field 'duration_s'", "must be > 0 (got -1)"]);
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.03\nduration_s = -0.5\n"
    ));
    assert_err(
        &e,
        8,
        &["event #1 (kind \"ramp\")", "field 'duration_s'", ">= 0"],
    );
}

#[test]
fn event_past_the_end() {
    // The second event in the file comes first in time: the message still says #2.
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 5.0\nkind = \"dither\"\nenabled = false\n[[event]]\nt_s = 0.5\nkind = \"retune\"\nenabled = false\n"
    ));
    assert_err(
        &e,
        4,
        &[
            "event #1 (kind \"dither\")",
            "field 't_s'",
            "inside the run",
            "5",
        ],
    );
}

#[test]
fn bad_measure_windows() {
    let e = load_err(&format!(
        "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 2.0\nto_s = 1.0\n"
    ));
    assert_err(
        &e,
        6,
        &["measure #1 (\"a\")", "field 'to_s'", "after its start"],
    );
    let e = load_err(&format!(
        "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 2.0\nto_s = 9.0\n"
    ));
    assert_err(&e, 6, &["field 'to_s'", "inside the run"]);
    let e = load_err(&format!(
        "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 1.0\nto_s = 2.0\nrun = \"twin\"\n"
    ));
    assert_err(&e, 7, &["field 'run'", "[twin]"]);
    let e = load_err(&format!(
        "{BASE}[[measure]]\nname = \"a\"\nfrom_s = 1.0\nto_s = 2.0\nrun = \"other\"\n"
    ));
    assert_err(&e, 7, &["field 'run'", "unknown value 'other'", "twin"]);
}

#[test]
fn non_finite_and_range_checks() {
    let e = load_err(&format!("{BASE}[plant]\nmu_x = nan\n"));
    assert_err(&e, 4, &["field 'plant.mu_x'", "finite"]);
    let e = load_err(&format!("{BASE}[sim]\nsteps_per_period = 8\n"));
    assert_err(&e, 4, &["field 'sim.steps_per_period'", ">= 16"]);
    let e = load_err(&format!("{BASE}[estimator]\nforgetting = 1.5\n"));
    assert_err(&e, 4, &["field 'estimator.forgetting'", "(0, 1]"]);
    let e = load_err(&format!("{BASE}[sim]\nnoise_pm_rthz = -1.0\n"));
    assert_err(&e, 4, &["field 'sim.noise_pm_rthz'"]);
    let e = load_err(&format!("{BASE}[twin.plant]\nwy2 = -1.0\n"));
    assert_err(&e, 4, &["field 'twin.plant.wy2'", "> 0"]);
    let e = load_err(&format!(
        "{BASE}[[event]]\nt_s = 1.0\nkind = \"pump_jump\"\ncentre_hz = 2e4\nto_sense_resonance = true\n"
    ));
    assert_err(&e, 3, &["event #1 (kind \"pump_jump\")", "not both"]);
}

#[test]
fn io_and_unknown_name_errors() {
    let e = Scenario::load("no-such-scenario").unwrap_err();
    assert_eq!(e.kind, ScenarioErrorKind::UnknownScenario);
    let msg = e.to_string();
    for (name, _) in Scenario::builtin_names() {
        assert!(msg.contains(name), "{msg}");
    }
    let e = Scenario::from_file(Path::new("/nonexistent/x.toml")).unwrap_err();
    assert_eq!(e.kind, ScenarioErrorKind::Io);
    assert!(e.to_string().starts_with("/nonexistent/x.toml: "), "{e}");
}

fn ramp_scenario() -> Scenario {
    Scenario::from_toml_str(
        &format!(
            "{BASE}[[event]]\nt_s = 2.0\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.03\nduration_s = 0.5\n"
        ),
        FILE,
    )
    .unwrap()
}

#[test]
fn plant_at_ramp() {
    let s = ramp_scenario();
    let wy2 = |t| s.plant_at(t).phys[4];
    assert_eq!(wy2(0.0), 1.0265);
    assert_eq!(wy2(2.0), 1.0265);
    assert!((wy2(2.25) - (1.0265 + 1.03) / 2.0).abs() < 1e-12);
    assert_eq!(wy2(2.5), 1.03);
    assert_eq!(wy2(3.9), 1.03);
    // θ22 follows: −(ωy² − γ²).
    let at = s.plant_at(2.25);
    let g = at.phys[10];
    assert!((at.theta_sense[1] + (wy2(2.25) - g * g)).abs() < 1e-15);
    // The rest of the plant is untouched.
    assert_eq!(at.phys[3], 1.0);
}

#[test]
fn ramps_chain_from_the_current_value() {
    let s = Scenario::from_toml_str(
        &format!(
            "{BASE}[[event]]\nt_s = 3.0\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = 0.0\nduration_s = 1.0\n\
             [[event]]\nt_s = 1.0\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = 300.0\nduration_s = 1.0\n"
        ),
        FILE,
    )
    .unwrap();
    assert_eq!(s.events[0].t_s, 1.0, "events are time-sorted");
    assert_eq!(s.plant_at(0.5).rate_dps, 150.0);
    assert_eq!(s.plant_at(1.5).rate_dps, 225.0);
    assert_eq!(s.plant_at(2.5).rate_dps, 300.0);
    assert_eq!(s.plant_at(3.5).rate_dps, 150.0);
    assert_eq!(s.plant_at(4.0).rate_dps, 0.0);
    // During a rate ramp γ' carries its slope (150 °/s per s).
    let w0 = s.omega0_rad_s();
    let gp = s.plant_at(1.5).phys[11];
    assert!((gp - 150f64.to_radians() / (w0 * w0)).abs() < 1e-20);
    assert_eq!(s.plant_at(2.5).phys[11], 0.0);
}

#[test]
fn plant_at_scale_theta() {
    let s = Scenario::from_toml_str(
        &format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"scale_theta\"\nfactor = 1.5\n\
             [[event]]\nt_s = 2.0\nkind = \"scale_theta\"\nfactor = 0.5\n\
             [[event]]\nt_s = 3.0\nkind = \"scale_theta\"\nfactor = 1.0\n"
        ),
        FILE,
    )
    .unwrap();
    let base = s.plant_at(0.0);
    for (t, f) in [(1.0, 1.5), (1.5, 1.5), (2.0, 0.5), (2.9, 0.5)] {
        let at = s.plant_at(t);
        for i in 0..8 {
            let want = if i == 7 { 1.0 } else { f * base.theta_drive[i] };
            assert!(
                (at.theta_drive[i] - want).abs() <= 1e-15 * want.abs(),
                "t={t} θ1{}",
                i + 1
            );
        }
        for i in 0..6 {
            let want = if i == 5 { 1.0 } else { f * base.theta_sense[i] };
            assert!(
                (at.theta_sense[i] - want).abs() <= 1e-15 * want.abs(),
                "t={t} θ2{}",
                i + 1
            );
        }
        assert!((at.rate_dps - 150.0 * f).abs() < 1e-9);
        // phys consistent with θ: γ scales, ωy² = −θ22 + γ².
        assert!((at.phys[10] - f * base.phys[10]).abs() < 1e-18);
        let g = at.phys[10];
        assert!((at.phys[4] - (-at.theta_sense[1] + g * g)).abs() < 1e-15);
    }
    assert_eq!(s.plant_at(3.0), base, "factor 1 restores");
    // The paper's re-centred pump (FINDINGS §3.5): √(−θ22) = 1.2409 at ×1.5.
    let w = (-s.plant_at(1.0).theta_sense[1]).sqrt();
    assert!((w - 1.2409).abs() < 1e-4, "{w}");
}

#[test]
fn pump_scale_and_control_events() {
    let s = Scenario::from_toml_str(
        &format!(
            "{BASE}[[event]]\nt_s = 1.0\nkind = \"pump_scale\"\ns = 0.8\nramp_s = 0.2\n\
             [[event]]\nt_s = 0.5\nkind = \"ramp\"\nparam = \"wy2\"\nto = 1.03\n\
             [[event]]\nt_s = 2.0\nkind = \"pump_jump\"\ncentre_hz = 21900.0\n\
             [[event]]\nt_s = 1.5\nkind = \"dither\"\nenabled = false\n"
        ),
        FILE,
    )
    .unwrap();
    assert_eq!(s.pump_scale_at(0.9), 1.0);
    assert!((s.pump_scale_at(1.1) - 0.9).abs() < 1e-12);
    assert_eq!(s.pump_scale_at(1.2), 0.8);
    let c = s.control_events();
    let kinds: Vec<&str> = c.iter().map(|e| e.kind.name()).collect();
    assert_eq!(kinds, ["pump_scale", "dither", "pump_jump"]);
    assert_eq!(s.pump_jump_centre_hz(&c[2]), Some(21900.0));
    // Step ramp (no duration): ωy² = 1.03 from 0.5 s on.
    assert_eq!(s.plant_at(0.5).phys[4], 1.03);
}

#[test]
fn every_builtin_loads_and_validates() {
    let names = Scenario::builtin_names();
    assert_eq!(names.len(), 5);
    for (name, desc) in names {
        let text = BUILTINS.iter().find(|b| b.0 == name).unwrap().2;
        let s = match Scenario::from_toml_str(text, name) {
            Ok(s) => s,
            Err(e) => panic!("built-in {name}: {e}"),
        };
        assert_eq!(s.name, name);
        assert!(!desc.is_empty() && !s.description.is_empty());
        s.validate().unwrap();
        let s = Scenario::builtin(name).unwrap();
        assert_eq!(s.source, "built-in");
        assert_eq!(Scenario::load(name).unwrap(), s);
        if let Some(t) = s.twin_scenario() {
            t.validate().unwrap();
            assert!(t.twin.is_none());
        }
    }
}

#[test]
fn builtin_specifics() {
    let pc_tuned = 2.0 * 1.0265f64.sqrt() * DEFAULT_F0_HZ;

    let s = Scenario::builtin("identify").unwrap();
    assert_eq!(s.duration_s, 10.0);
    assert_eq!(s.estimator.nominal.wy2, 1.03);
    assert!((s.pump_centre_hz() - pc_tuned).abs() < 0.01);
    let (nd, ns) = s.nominal_theta();
    let at = s.plant_at(0.0);
    for (n, t) in nd
        .iter()
        .chain(&ns)
        .zip(at.theta_drive.iter().chain(&at.theta_sense))
    {
        let rel = ((n - t) / t).abs();
        assert!(rel < 0.5, "nominal θ {n} vs true {t}");
    }
    assert!(nd[..7].iter().zip(&at.theta_drive).any(|(n, t)| n != t));

    let s = Scenario::builtin("drift-retune").unwrap();
    assert_eq!(s.duration_s, 8.0);
    assert_eq!(s.plant_at(1.0).phys[4], 1.0265);
    assert_eq!(s.plant_at(2.5).phys[4], 1.03);
    assert!((s.pump_centre_hz() - pc_tuned).abs() < 0.01);
    let twin = s.twin_scenario().unwrap();
    assert!(!twin.estimator.retune);
    assert_eq!(twin.plant_at(3.0).phys[4], 1.03);
    assert_eq!(s.measures.len(), 3);
    assert!(s.estimator.retune);
    assert!(
        s.control_events()
            .iter()
            .any(|e| e.t_s == 6.0 && matches!(e.kind, EventKind::Dither { enabled: false, .. }))
    );

    let s = Scenario::builtin("paper-switch").unwrap();
    let jumps: Vec<f64> = s
        .control_events()
        .iter()
        .filter_map(|e| s.pump_jump_centre_hz(e))
        .collect();
    assert_eq!(jumps.len(), 2);
    // ω = 1.2409 and 0.7164 (FINDINGS §3.5).
    assert!((jumps[0] / (2.0 * s.sim.f0_hz) - 1.2409).abs() < 1e-4);
    assert!((jumps[1] / (2.0 * s.sim.f0_hz) - 0.7164).abs() < 1e-4);
    assert!(!s.estimator.retune);

    let s = Scenario::builtin("paper-claim").unwrap();
    assert!((s.pump_centre_hz() - pc_tuned).abs() < 0.01);
    let twin = s.twin_scenario().unwrap();
    assert_eq!(twin.plant_at(0.0).phys[4], 1.03);
    assert_eq!(twin.pump_centre_hz(), s.pump_centre_hz());
    assert!(!s.estimator.retune);
}

#[test]
fn readme_example_loads() {
    let readme = include_str!("../../../scenarios/README.md");
    let example = readme
        .split("## Example")
        .nth(1)
        .and_then(|r| r.split("```toml\n").nth(1))
        .and_then(|r| r.split("```").next())
        .expect("README has a ```toml example");
    let s = Scenario::from_toml_str(example, "README.md").unwrap();
    assert_eq!(s.events.len(), 3);
    assert!((s.plant_at(7.0).phys[4] - 1.0285).abs() < 1e-12);
    assert!((s.plant_at(6.0).rate_dps - 300.0).abs() < 1e-12);
    assert!(s.twin_scenario().is_some());
}

#[test]
fn measure_values_average_the_sense_amplitude() {
    let s = Scenario::builtin("paper-claim").unwrap();
    let row = |t: f64, amp: f64| TraceRow {
        t_s: t,
        pump_hz: 0.0,
        pump_centre_hz: 0.0,
        pump_scale: 1.0,
        theta_drive_true: [0.0; 8],
        theta_sense_true: [0.0; 6],
        theta_drive_est: [0.0; 8],
        theta_sense_est: [0.0; 6],
        phys_true: [0.0; 12],
        phys_est: [0.0; 12],
        rate_dps_true: 0.0,
        rate_dps_est: 0.0,
        drive_amp_um: 0.0,
        sense_amp_um: amp,
        health: 0,
        resets: 0,
        bad_samples: 0,
        rate_dps_slow: 0.0,
        quadrature_dps: 0.0,
        rate_valid: false,
        temp_c: f64::NAN,
        drift_ppm_s: [0.0; 2],
        tcf_ppm_k: [f64::NAN; 2],
        drift_alarms: 0,
    };
    let main: Vec<TraceRow> = (0..1000).map(|k| row(k as f64 * 0.002, 1.5)).collect();
    let twin: Vec<TraceRow> = (0..1000).map(|k| row(k as f64 * 0.002, 0.75)).collect();
    let v = s.measure_values(&main, Some(&twin));
    assert_eq!(v[0], ("sense_amp_tuned".to_string(), Some(1.5)));
    assert_eq!(v[1], ("sense_amp_detuned".to_string(), Some(0.75)));
    let v = s.measure_values(&main, None);
    assert_eq!(v[1].1, None);
}
