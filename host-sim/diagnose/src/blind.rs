//! The blind benchmark of the diagnosis (`paragyro-sim blind`): records whose effect is
//! withheld, labels sealed before any diagnosis runs, then scored.
//!
//! 1. **Draw** N records of the `characterise` scenario from the seed: 20 % clean, 50 % one
//!    library effect, 15 % two library effects, 15 % one effect outside the library. Sizes
//!    are log-uniform over [`RANGES`] (which reach below the stated detection limits), signs
//!    random where the effect has both, the angular-vibration beat uniform in ±[0.5, 5] Hz.
//!    Every record has a rate table (`rate_ref_dps`) and a die temperature rising by a random
//!    2–8 K, so neither column gives the label away.
//! 2. **Seal**: all records are written, then `labels.json`, before the first diagnosis.
//! 3. **Diagnose** each record from its CSV alone ([`crate::diagnose::diagnose`]).
//! 4. **Score** (labels read only now): confusion matrix, top-1 accuracy on single library
//!    effects above their detection limit, `unknown` on out-of-library records, false
//!    alarms on clean ones, output-error gap closure against the oracle's (the simulator
//!    re-run with the true effects at their true sizes), detection rate against size.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde_json::{Value, json};

use crate::diagnose::{self, Model, Options};
use paragyro_simulator::effects::{EffectSpec, LIBRARY, OUT_OF_LIBRARY};
use paragyro_simulator::record::{self, RecordOptions};
use paragyro_simulator::scenario::Scenario;

/// Size range drawn for each effect (log-uniform magnitude) and the stated detection limit
/// (the size above which the diagnosis is claimed to name it), fixed before the scored run.
/// (name, low, high, detection limit, signed)
pub const RANGES: [(&str, f64, f64, f64, bool); 11] = [
    ("geometric_nonlinearity", 1e-9, 1e-5, 1e-7, true),
    ("angular_vibration", 1.0, 60.0, 20.0, false),
    ("electrostatic_softening", 1e-9, 1e-5, 1e-7, false),
    ("feedthrough", 1e-6, 1e-2, 1e-4, true),
    ("nonlinear_damping", 1e-9, 1e-5, 1e-7, false),
    ("anisodamping", 1e-9, 1e-5, 1e-7, true),
    ("force_leak", 1e-7, 1e-3, 1e-5, true),
    ("thermal_drift", 0.05, 50.0, 1.0, false),
    ("lockin_mismatch", 1e-5, 1e-1, 1e-3, true),
    ("quadratic_stiffness", 1e-7, 1e-4, 1e-6, true),
    ("readout_gain", 1e-5, 3e-2, 1e-3, true),
];

fn range(name: &str) -> (f64, f64, f64, bool) {
    RANGES
        .iter()
        .find(|r| r.0 == name)
        .map_or((1.0, 1.0, 1.0, false), |r| (r.1, r.2, r.3, r.4))
}

/// One drawn record.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Draw {
    /// Record id.
    pub id: String,
    /// Category: none, single, double, outside.
    pub category: String,
    /// Effects with their true sizes.
    pub effects: Vec<EffectSpec>,
    /// Noise seed.
    pub seed: u64,
    /// Temperature rise, K.
    pub temp_rise_k: f64,
}

fn draw_effect(rng: &mut Xoshiro256PlusPlus, name: &str) -> EffectSpec {
    let (lo, hi, _, signed) = range(name);
    let mut size = (lo.ln() + rng.random::<f64>() * (hi.ln() - lo.ln())).exp();
    if name == "thermal_drift" || (signed && rng.random::<bool>()) {
        size = -size; // TCF is negative in silicon
    }
    let param = (name == "angular_vibration").then(|| {
        let b = 0.5 + 4.5 * rng.random::<f64>();
        let b = (b * 100.0).round() / 100.0;
        if rng.random::<bool>() { b } else { -b }
    });
    EffectSpec {
        name: name.into(),
        size,
        param,
    }
}

/// Draws the N records' labels from `seed`.
pub fn draw(n: usize, seed: u64) -> Vec<Draw> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x5eed_b11d);
    (0..n)
        .map(|i| {
            let u: f64 = rng.random();
            let pick_lib =
                |rng: &mut Xoshiro256PlusPlus| LIBRARY[rng.random_range(0..LIBRARY.len())];
            let (category, effects) = if u < 0.2 {
                ("none", Vec::new())
            } else if u < 0.7 {
                let e = pick_lib(&mut rng);
                ("single", vec![draw_effect(&mut rng, e)])
            } else if u < 0.85 {
                let a = pick_lib(&mut rng);
                let mut b = pick_lib(&mut rng);
                while b == a {
                    b = pick_lib(&mut rng);
                }
                (
                    "double",
                    vec![draw_effect(&mut rng, a), draw_effect(&mut rng, b)],
                )
            } else {
                let e = OUT_OF_LIBRARY[rng.random_range(0..OUT_OF_LIBRARY.len())];
                ("outside", vec![draw_effect(&mut rng, e)])
            };
            Draw {
                id: format!("rec-{i:03}"),
                category: category.into(),
                effects,
                seed: rng.random::<u32>() as u64,
                temp_rise_k: ((2.0 + 6.0 * rng.random::<f64>()) * 100.0).round() / 100.0,
            }
        })
        .collect()
}

/// One scored record.
#[derive(Clone, Debug, serde::Serialize)]
struct Scored {
    id: String,
    category: String,
    truth: Vec<String>,
    sizes: Vec<f64>,
    verdict: String,
    secondary: Option<String>,
    correct: bool,
    above_limit: bool,
    size_over_limit: f64,
    oe_closure: Option<f64>,
    oracle_closure: Option<f64>,
    fitted_size: Option<f64>,
    seconds: f64,
}

/// Runs the benchmark into `dir` (records/, labels.json, diagnoses/, score.json, score.md).
/// `progress` gets messages.
pub fn run(
    n: usize,
    seed: u64,
    dir: &Path,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Value> {
    let sc = Scenario::load("characterise").map_err(anyhow::Error::new)?;
    let draws = draw(n, seed);
    let rec_dir = dir.join("records");
    std::fs::create_dir_all(&rec_dir)
        .with_context(|| format!("cannot create {}", rec_dir.display()))?;

    // 1. records (two at a time), 2. the sealed labels
    let t0 = Instant::now();
    let paths: Vec<PathBuf> = draws
        .iter()
        .map(|d| rec_dir.join(format!("{}.csv", d.id)))
        .collect();
    let results: Vec<anyhow::Result<()>> = std::thread::scope(|s| {
        let chunks: Vec<Vec<usize>> = (0..2).map(|c| (c..n).step_by(2).collect()).collect();
        let hs: Vec<_> = chunks
            .into_iter()
            .map(|ix| {
                let (sc, draws, paths) = (&sc, &draws, &paths);
                s.spawn(move || {
                    ix.into_iter()
                        .map(|i| {
                            let d = &draws[i];
                            let opts = RecordOptions {
                                seed: Some(d.seed),
                                effects: d.effects.clone(),
                                rate_table: true,
                                temp: Some((25.0, d.temp_rise_k)),
                            };
                            record::write_simulated_record(sc, &paths[i], &opts, &mut |_| {})
                                .map(|_| ())
                        })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        hs.into_iter()
            .flat_map(|h| h.join().unwrap_or_default())
            .collect()
    });
    for r in results {
        r?;
    }
    progress(&format!(
        "wrote {n} records in {:.0} s",
        t0.elapsed().as_secs_f64()
    ));
    let labels = dir.join("labels.json");
    std::fs::write(
        &labels,
        serde_json::to_string_pretty(&json!({"seed": seed, "records": draws}))? + "\n",
    )
    .with_context(|| format!("cannot write {}", labels.display()))?;
    progress(&format!("sealed the labels in {}", labels.display()));

    // 3. diagnoses, from the CSV alone
    let diag_dir = dir.join("diagnoses");
    let mut reports: Vec<Value> = Vec::with_capacity(n);
    for (i, p) in paths.iter().enumerate() {
        let rec = record::read_record(p).map_err(anyhow::Error::new)?;
        let d = diagnose::diagnose(&rec, &Options::default())
            .with_context(|| format!("diagnosing {}", p.display()))?;
        let out = diag_dir.join(&draws[i].id);
        std::fs::create_dir_all(&out)?;
        std::fs::write(
            out.join("report.json"),
            serde_json::to_string_pretty(&d.json)? + "\n",
        )?;
        progress(&format!("[{}/{n}] {} → {}", i + 1, draws[i].id, d.verdict));
        reports.push(d.json);
    }

    // 4. score (labels used from here on)
    let mut scored = Vec::with_capacity(n);
    for (i, d) in draws.iter().enumerate() {
        let r = &reports[i];
        let verdict = r["verdict"].as_str().unwrap_or("").to_string();
        let secondary = r["secondary"]["effect"].as_str().map(String::from);
        let truth: Vec<String> = d.effects.iter().map(|e| e.name.clone()).collect();
        let correct = match d.category.as_str() {
            "none" => verdict == "none",
            "outside" => verdict == "unknown",
            _ => truth.contains(&verdict),
        };
        let ratio = d
            .effects
            .iter()
            .map(|e| e.size.abs() / range(&e.name).2)
            .fold(0.0f64, f64::max);
        let oe_closure = r["output_error"]["closure"].as_f64();
        // the oracle: the simulator with the true effects at their true sizes, same span
        let oracle_closure = if d.category == "single" || d.category == "double" {
            let rec = record::read_record(&paths[i]).map_err(anyhow::Error::new)?;
            oracle(&rec, r, &d.effects).ok()
        } else {
            None
        };
        let fitted_size = r["ranking"]
            .as_array()
            .and_then(|a| a.iter().find(|c| c["effect"] == json!(verdict)))
            .and_then(|c| c["size"].as_f64());
        scored.push(Scored {
            id: d.id.clone(),
            category: d.category.clone(),
            truth,
            sizes: d.effects.iter().map(|e| e.size).collect(),
            verdict,
            secondary,
            correct,
            above_limit: ratio >= 1.0,
            size_over_limit: ratio,
            oe_closure,
            oracle_closure,
            fitted_size,
            seconds: r["seconds"].as_f64().unwrap_or(f64::NAN),
        });
    }
    let summary = summarize(&scored, n, seed);
    std::fs::write(
        dir.join("score.json"),
        serde_json::to_string_pretty(&json!({"summary": summary, "records": scored}))? + "\n",
    )?;
    std::fs::write(dir.join("score.md"), markdown(&summary, &scored))?;
    Ok(summary)
}

/// Output-error closure of the true effects at their true sizes on the diagnosis's
/// held-out span (the same re-simulation and error measure as the diagnosis).
fn oracle(rec: &record::Record, report: &Value, effects: &[EffectSpec]) -> anyhow::Result<f64> {
    let before = report["output_error"]["before"]["above_noise"]
        .as_f64()
        .context("no output error in the report")?;
    let span = &report["spans_s"]["held_out"];
    let (t0, t1) = (
        span[0].as_f64().unwrap_or(0.0),
        span[1].as_f64().unwrap_or(0.0),
    );
    let k0 = rec
        .rows
        .iter()
        .position(|r| r.t_s >= t0 - 1e-9)
        .unwrap_or(0);
    let k1 = rec
        .rows
        .iter()
        .rposition(|r| r.t_s <= t1 + 1e-9)
        .map_or(rec.rows.len(), |k| k + 1);
    let rr: Vec<f64> = rec
        .rows
        .iter()
        .map(|r| r.rate_ref_dps.unwrap_or(0.0))
        .collect();
    let sim = diagnose::Resim {
        rec,
        model: &Model::table2(),
        gamma: None,
        rate_ref: Some(&rr),
        effects,
        vib_phase0: 0.0,
        steps_per_period: 128,
    }
    .run(k0..k1)?;
    let mut full = vec![paragyro_simulator::lockin::LockinOut::default(); rec.rows.len()];
    full[k0..k1].clone_from_slice(&sim);
    let ratio = report["output_error"]["noise_diff_ratio"]
        .as_f64()
        .context("no noise ratio")?;
    let e = diagnose::output_error(rec, &full, k0..k1, ratio);
    Ok(1.0 - e.above_noise / before.max(1e-300))
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    Some(v[v.len() / 2])
}

fn summarize(s: &[Scored], n: usize, seed: u64) -> Value {
    let frac = |num: usize, den: usize| {
        if den > 0 {
            num as f64 / den as f64
        } else {
            f64::NAN
        }
    };
    let single_above: Vec<&Scored> = s
        .iter()
        .filter(|r| r.category == "single" && r.above_limit)
        .collect();
    let outside: Vec<&Scored> = s.iter().filter(|r| r.category == "outside").collect();
    let clean: Vec<&Scored> = s.iter().filter(|r| r.category == "none").collect();
    let double: Vec<&Scored> = s.iter().filter(|r| r.category == "double").collect();
    let false_attr = outside
        .iter()
        .filter(|r| r.verdict != "unknown" && r.verdict != "none")
        .count();
    let ratios: Vec<f64> = s
        .iter()
        .filter(|r| r.category == "single" && r.above_limit)
        .filter_map(|r| match (r.oe_closure, r.oracle_closure) {
            (Some(a), Some(o)) if o > 0.0 => Some(a / o),
            _ => None,
        })
        .collect();
    // confusion: truth (first effect / none / outside) → verdict
    let mut conf: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for r in s {
        let t = match r.category.as_str() {
            "none" => "none".to_string(),
            "outside" => format!("outside:{}", r.truth[0]),
            "double" => "two effects".to_string(),
            _ => r.truth[0].clone(),
        };
        *conf
            .entry(t)
            .or_default()
            .entry(r.verdict.clone())
            .or_default() += 1;
    }
    // detection rate against size (single library effects), by size / limit
    let bins = [(0.0, 0.3), (0.3, 1.0), (1.0, 10.0), (10.0, f64::INFINITY)];
    let det: Vec<Value> = bins
        .iter()
        .map(|&(a, b)| {
            let v: Vec<&Scored> = s
                .iter()
                .filter(|r| r.category == "single" && r.size_over_limit >= a && r.size_over_limit < b)
                .collect();
            json!({"size_over_limit": [a, if b.is_finite() { json!(b) } else { json!("inf") }], "records": v.len(),
                   "named_correctly": frac(v.iter().filter(|r| r.correct).count(), v.len()),
                   "said_none": frac(v.iter().filter(|r| r.verdict == "none").count(), v.len())})
        })
        .collect();
    json!({
        "n": n,
        "seed": seed,
        "top1_single_above_limit": frac(single_above.iter().filter(|r| r.correct).count(), single_above.len()),
        "single_above_limit_records": single_above.len(),
        "unknown_on_outside": frac(outside.iter().filter(|r| r.verdict == "unknown").count(), outside.len()),
        "unknown_on_outside_above_limit": frac(
            outside.iter().filter(|r| r.above_limit && r.verdict == "unknown").count(),
            outside.iter().filter(|r| r.above_limit).count()
        ),
        "outside_above_limit_records": outside.iter().filter(|r| r.above_limit).count(),
        "top1_single_all_sizes": frac(
            s.iter().filter(|r| r.category == "single" && r.correct).count(),
            s.iter().filter(|r| r.category == "single").count()
        ),
        "false_attribution_on_outside": frac(false_attr, outside.len()),
        "outside_records": outside.len(),
        "false_alarms_on_clean": frac(clean.iter().filter(|r| r.verdict != "none").count(), clean.len()),
        "clean_records": clean.len(),
        "double_one_named": frac(double.iter().filter(|r| r.correct).count(), double.len()),
        "double_both_named": frac(double.iter().filter(|r| r.correct && r.secondary.as_ref().is_some_and(|x| r.truth.contains(x))).count(), double.len()),
        "double_records": double.len(),
        "median_closure_over_oracle": median(ratios.clone()),
        "median_oe_closure_single_above": median(single_above.iter().filter_map(|r| r.oe_closure).collect()),
        "median_oracle_closure_single_above": median(single_above.iter().filter_map(|r| r.oracle_closure).collect()),
        "confusion": conf,
        "detection_vs_size": det,
        "median_diagnosis_seconds": median(s.iter().map(|r| r.seconds).collect()),
        "limits": RANGES.iter().map(|r| json!({"effect": r.0, "low": r.1, "high": r.2, "detection_limit": r.3})).collect::<Vec<_>>(),
        "thresholds": {"t_sig": diagnose::T_SIG, "gap_min": diagnose::GAP_MIN, "share_min": diagnose::SHARE_MIN},
    })
}

fn markdown(sm: &Value, s: &[Scored]) -> String {
    let p = |v: &Value| {
        v.as_f64()
            .map_or("–".into(), |x| format!("{:.0} %", 100.0 * x))
    };
    let mut m = format!(
        "# Blind benchmark of the diagnosis (N = {}, seed {})\n\n| measure | result | target |\n|---|---|---|\n",
        sm["n"], sm["seed"]
    );
    m.push_str(&format!("| top-1 on single library effects above the detection limit ({} records) | {} | ≥ 90 % |\n", sm["single_above_limit_records"], p(&sm["top1_single_above_limit"])));
    m.push_str(&format!(
        "| `unknown` on out-of-library records ({}) | {} | ≥ 80 % |\n",
        sm["outside_records"],
        p(&sm["unknown_on_outside"])
    ));
    m.push_str(&format!(
        "| `unknown` on out-of-library records above their detection limit ({}) | {} | |\n",
        sm["outside_above_limit_records"],
        p(&sm["unknown_on_outside_above_limit"])
    ));
    m.push_str(&format!(
        "| false attribution on out-of-library records | {} | |\n",
        p(&sm["false_attribution_on_outside"])
    ));
    m.push_str(&format!(
        "| top-1 on single library effects, all sizes (`none` below the limit counts as a miss) | {} | |\n",
        p(&sm["top1_single_all_sizes"])
    ));
    m.push_str(&format!(
        "| false alarms on clean records ({}) | {} | ≤ 10 % |\n",
        sm["clean_records"],
        p(&sm["false_alarms_on_clean"])
    ));
    m.push_str(&format!("| median output-error gap closure / oracle closure (single, above limit) | {} | ≥ 80 % |\n", p(&sm["median_closure_over_oracle"])));
    m.push_str(&format!(
        "| two effects: one named / both named ({}) | {} / {} | |\n",
        sm["double_records"],
        p(&sm["double_one_named"]),
        p(&sm["double_both_named"])
    ));
    m.push_str(&format!(
        "| median diagnosis time (20 s record) | {:.2} s | |\n",
        sm["median_diagnosis_seconds"].as_f64().unwrap_or(f64::NAN)
    ));
    m.push_str("\n## Detection against size (single library effects)\n\n| size / detection limit | records | named correctly | said none |\n|---|---|---|---|\n");
    if let Some(a) = sm["detection_vs_size"].as_array() {
        for b in a {
            m.push_str(&format!(
                "| {}–{} | {} | {} | {} |\n",
                b["size_over_limit"][0],
                b["size_over_limit"][1],
                b["records"],
                p(&b["named_correctly"]),
                p(&b["said_none"])
            ));
        }
    }
    m.push_str("\n## Confusion (truth → verdict)\n\n");
    if let Some(c) = sm["confusion"].as_object() {
        for (t, v) in c {
            let cells: Vec<String> = v.as_object().map_or(Vec::new(), |o| {
                o.iter().map(|(k, n)| format!("{k}: {n}")).collect()
            });
            m.push_str(&format!("- **{t}** → {}\n", cells.join(", ")));
        }
    }
    m.push_str("\n## Records\n\n| id | category | truth (size) | verdict | OE closure | oracle |\n|---|---|---|---|---|---|\n");
    for r in s {
        let truth: Vec<String> = r
            .truth
            .iter()
            .zip(&r.sizes)
            .map(|(t, z)| format!("{t} ({z:.3e})"))
            .collect();
        let f = |v: Option<f64>| v.map_or("–".into(), |x| format!("{:.1} %", 100.0 * x));
        m.push_str(&format!(
            "| {} | {} | {} | {}{} | {} | {} |\n",
            r.id,
            r.category,
            truth.join(", "),
            r.verdict,
            r.secondary
                .as_ref()
                .map(|x| format!(" + {x}"))
                .unwrap_or_default(),
            f(r.oe_closure),
            f(r.oracle_closure)
        ));
    }
    m
}
