//! report.json round-trips through serde: any report (verdicts with and without a second
//! effect, tested and untestable candidates, with and without the re-simulation, either
//! rate source) serialises and deserialises to itself, and its keys are report.json's.

use std::collections::BTreeMap;

use paragyro_diagnose::diagnose::calibrate::{FaceHypothesis, ParamDeviation, ParameterFace};
use paragyro_diagnose::diagnose::confirm::{Pair, Run, Stop, WithoutRegrowths};
use paragyro_diagnose::diagnose::locate::{AxisShare, Regime, RowEnergy, Tercile, TimeSpan, Where};
use paragyro_diagnose::diagnose::report::{BeatScan, Confirmation, FORMAT, Limitation};
use paragyro_diagnose::diagnose::{
    Answer, Candidate, Energies, HowFar, OutputError, Rate, Report, Secondary, Separation,
    SpansReport, Thresholds, Verdict,
};
use paragyro_simulator::effects::Effect;
use proptest::prelude::*;
use proptest::strategy::ValueTree;

fn effect() -> impl Strategy<Value = Effect> {
    prop::sample::select(Effect::ALL.to_vec())
}

fn num() -> impl Strategy<Value = f64> {
    prop_oneof![-1e3f64..1e3, -1e-6f64..1e-6, Just(0.0)]
}

fn verdict() -> impl Strategy<Value = Verdict> {
    prop_oneof![
        Just(Verdict::None),
        Just(Verdict::Unknown),
        (effect(), prop::option::of((effect(), num()))).prop_map(|(primary, s)| {
            Verdict::Effects {
                primary,
                secondary: s.map(|(effect, added_closure)| Secondary {
                    effect,
                    added_closure,
                }),
            }
        }),
    ]
}

fn answer() -> impl Strategy<Value = Answer> {
    prop_oneof![
        Just(Answer::None),
        Just(Answer::Unknown),
        effect().prop_map(Answer::Effect)
    ]
}

fn candidate() -> impl Strategy<Value = Candidate> {
    (
        effect(),
        prop::option::of((num(), num())),
        (num(), any::<bool>(), num(), num(), num()),
        prop::collection::vec(effect(), 0..3),
        prop::option::of(num()),
    )
        .prop_map(
            |(effect, size, (gc, sig, ef, db, re), coherent_with, beat_hz)| Candidate {
                effect,
                untestable: size.is_none().then(|| "no temp_c column".to_string()),
                size: size.map(|s| s.0),
                size_sigma: size.map(|s| s.1),
                gap_closure: gc,
                significant: sig,
                energy_fraction: ef,
                delta_bic: db,
                residual_explainable: re,
                coherent_with,
                beat_hz,
            },
        )
}

fn output_error() -> impl Strategy<Value = OutputError> {
    (num(), num(), num(), num()).prop_map(|(drive, sense, combined, above_noise)| OutputError {
        drive,
        sense,
        combined,
        above_noise,
    })
}

fn how_far() -> impl Strategy<Value = HowFar> {
    (
        output_error(),
        output_error(),
        num(),
        prop::option::of(num()),
    )
        .prop_map(|(before, after, closure, rate_dps)| HowFar {
            held_out_span_s: [12.5, 19.998],
            before,
            after,
            closure,
            closure_raw: closure / 2.0,
            noise_diff_ratio: 1.9,
            added: vec!["feedthrough=0.003".into()],
            rate_dps,
            note: "rms".into(),
        })
}

fn place() -> impl Strategy<Value = Where> {
    (
        num(),
        prop::collection::vec((prop::option::of(num()), num()), 3),
        num(),
    )
        .prop_map(|(share, terciles, correlation)| Where {
            axis: AxisShare {
                drive: share,
                sense: 1.0 - share,
            },
            channel: BTreeMap::from([("drive/DC".into(), share), ("sense/DC".into(), 0.5)]),
            regime: vec![Regime {
                quantity: "drive amplitude (µm)".into(),
                terciles: terciles
                    .into_iter()
                    .map(|(from, relative_gap_density)| Tercile {
                        from,
                        to: from.map(|f| f + 1.0),
                        relative_gap_density,
                    })
                    .collect(),
                correlation,
            }],
            time: TimeSpan {
                half_of_gap_within_s: [1.0, 2.5],
                fraction_of_time_holding_half: share,
                cusum_extreme_at_s: 3.25,
            },
        })
}

fn confirmation() -> impl Strategy<Value = Confirmation> {
    (
        "[a-z_]{3,20}=[0-9.e-]{1,8}",
        num(),
        prop::collection::vec(0usize..10, 0..3),
        num(),
        num(),
        any::<bool>(),
        prop::collection::vec((num(), num(), num(), any::<bool>()), 1..4),
        prop::option::of(prop_oneof![
            Just(Stop::Converged),
            Just(Stop::Hopeless),
            Just(Stop::Budget),
            Just(Stop::Failed)
        ]),
        prop::option::of(num()),
        prop::option::of(
            (
                prop::option::of("[a-z_]{3,20}=[0-9.e-]{1,8}"),
                "[a-z_]{3,20}=[0-9.e-]{1,8}",
                num(),
                num(),
                prop::option::of((num(), num())),
            )
                .prop_map(
                    |(first, effect, unexplained, residual_over_noise, outside)| Pair {
                        first,
                        effect,
                        unexplained,
                        residual_over_noise,
                        outside_regrowths: outside.map(|(share, residual_over_noise_with)| {
                            WithoutRegrowths {
                                share,
                                residual_over_noise_with,
                            }
                        }),
                    },
                ),
        ),
        prop::option::of(
            (num(), num()).prop_map(|(share, residual_over_noise_with)| WithoutRegrowths {
                share,
                residual_over_noise_with,
            }),
        ),
    )
        .prop_map(
            |(
                effect,
                unexplained,
                unexplained_rows,
                residual_over_noise,
                nu2,
                confirmed,
                runs,
                stopped,
                next_step,
                with,
                outside_regrowths,
            )| {
                Confirmation {
                    effect,
                    unexplained,
                    unexplained_rows,
                    residual_over_noise,
                    noise_energy_ratio: nu2,
                    confirmed,
                    runs: runs
                        .into_iter()
                        .map(|(size, unexplained, residual_over_noise, passed)| Run {
                            size,
                            unexplained,
                            residual_over_noise,
                            passed,
                        })
                        .collect(),
                    stopped,
                    next_step,
                    with,
                    outside_regrowths,
                }
            },
        )
}

fn report() -> impl Strategy<Value = Report> {
    (
        verdict(),
        prop::collection::vec(candidate(), 0..6),
        (num(), num(), num(), num(), num()),
        answer(),
        prop::option::of(how_far()),
        place(),
        prop::option::of(prop::option::of(num())),
        (
            prop::collection::vec(
                (prop::collection::vec(effect(), 1..3), "[a-z ]{0,12}"),
                0..3,
            ),
            prop::collection::vec(confirmation(), 0..3),
        ),
    )
        .prop_map(
            |(
                verdict,
                ranking,
                (gb, ga, gc, gf, un),
                closest,
                far,
                location,
                rate,
                (sep, conf),
            )| Report {
                format: FORMAT.into(),
                verdict,
                ranking,
                gap_before: gb,
                gap_after: ga,
                gap_closure: gc,
                gap_fraction_of_baseline: gf,
                unexplained_above_noise: un,
                unexplained_rows: vec!["drive/DC".into()],
                closest_library_effect: closest,
                held_out_by_row: vec![RowEnergy {
                    row: 3,
                    baseline: gb,
                    closest: ga,
                    everything: gc,
                }],
                energies: Energies {
                    note: "weighted".into(),
                    baseline: gb,
                    catch_all: ga,
                    floor: gc,
                    after: gf,
                    rows: 41_000,
                },
                output_error: far,
                parameter_face: ParameterFace {
                    parameters: vec![ParamDeviation {
                        name: "wy2".into(),
                        model: 1.0265,
                        device: 1.0275 + gb,
                        sigma: 1e-8,
                        relative: Some(0.001),
                        relative_sigma: Some(1e-8),
                        t: 1e5,
                    }],
                    hypotheses: vec![FaceHypothesis {
                        name: "tolerance".into(),
                        status: "null".into(),
                        size: None,
                        sigma: Some(ga),
                        detail: "independent".into(),
                    }],
                    rate_offset_dps: rate.flatten(),
                    noise_energy_ratio: 1.02,
                    resimulations: 2,
                },
                residual_over_noise: un,
                noise_per_row: vec![gb, un],
                confirmation: conf,
                location,
                model: "Table 2 (default)".into(),
                rate: match rate {
                    None => Rate::Table,
                    Some(rate_dps) => Rate::Fitted { rate_dps },
                },
                spans_s: SpansReport {
                    fit: [0.5, 11.9],
                    guard_s: 0.5,
                    held_out: [12.4, 20.0],
                },
                thresholds: Thresholds::current(),
                vibration_beat_scan: BeatScan {
                    range_hz: 6.0,
                    best_hz: gc,
                    dither_hz: vec![5.0, 1.3],
                },
                separating_excitation: sep
                    .into_iter()
                    .map(|(pair, excitation)| Separation { pair, excitation })
                    .collect(),
                samples: 10_001,
                seconds: 3.5,
                timing_s: BTreeMap::from([("rows".into(), 0.25)]),
                limitations: Vec::new(),
            },
        )
}

/// The keys of report.json (format 3: format 2's — format 1's and the parameter face — and
/// the confirmation by re-simulation).
const KEYS: [&str; 28] = [
    "closest_library_effect",
    "confirmation",
    "energies",
    "format",
    "gap_after",
    "gap_before",
    "gap_closure",
    "gap_fraction_of_baseline",
    "held_out_by_row",
    "model",
    "noise_per_row",
    "output_error",
    "parameter_face",
    "ranking",
    "rate",
    "residual_over_noise",
    "samples",
    "secondary",
    "seconds",
    "separating_excitation",
    "spans_s",
    "thresholds",
    "timing_s",
    "unexplained_above_noise",
    "unexplained_rows",
    "verdict",
    "vibration_beat_scan",
    "where",
];

proptest! {
    #[test]
    fn report_round_trips_through_serde(r in report()) {
        let v = serde_json::to_value(&r).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
        prop_assert_eq!(keys, KEYS.to_vec());
        let name = r.verdict.to_string();
        prop_assert_eq!(v["verdict"].as_str(), Some(name.as_str()));
        let back: Report = serde_json::from_value(v).unwrap();
        prop_assert_eq!(back, r);
    }
}

/// A report with limitations (issue 31) has the key `limitations` besides format 3's, and
/// round-trips; report.md lists them.
#[test]
fn limitations_are_a_key_when_there_are_some() {
    let mut r = report()
        .new_tree(&mut proptest::test_runner::TestRunner::deterministic())
        .unwrap()
        .current();
    r.limitations = vec![Limitation::new(
        "calibration",
        "the first fit estimated a model that is not physical",
    )];
    let v = serde_json::to_value(&r).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    let mut want = KEYS.to_vec();
    want.push("limitations");
    want.sort_unstable();
    assert_eq!(keys, want);
    assert_eq!(v["limitations"][0]["stage"], "calibration");
    let back: Report = serde_json::from_value(v).unwrap();
    assert_eq!(back, r);
    let md = r.markdown("rec.csv");
    assert!(
        md.contains("## Limitations") && md.contains("**calibration**: the first fit"),
        "{md}"
    );
}

#[test]
fn a_secondary_effect_needs_a_primary() {
    let r = report()
        .prop_filter("a verdict none", |r| r.verdict == Verdict::None)
        .new_tree(&mut proptest::test_runner::TestRunner::deterministic())
        .unwrap()
        .current();
    let mut v = serde_json::to_value(&r).unwrap();
    v["secondary"] = serde_json::json!({"effect": "feedthrough", "added_closure": 0.2});
    let err = serde_json::from_value::<Report>(v).unwrap_err().to_string();
    assert!(
        err.contains("a secondary effect (feedthrough) with the verdict 'none'"),
        "{err}"
    );
}
