//! Issue 31: the diagnosis is total over valid records. A seeded property test of the whole
//! pipeline over generated records: random protocols (length, pump-frequency dither
//! frequency and amplitude, pump-amplitude dither and steps, a rate profile with a
//! reversal through a short ramp, a rate table or not, a die-temperature ramp or not) on
//! toleranced devices ([`blind::device::DeviceDraw`]), with random effects in the library
//! (none, one or two, sizes log-uniform over the blind benchmark's ranges stretched ×10
//! above) or outside it (`blind::outside`, through the plant hook), and in a quarter of them
//! a run of 1–400 rows with one column non-finite (NaN, ∞; or the rate table's value
//! missing), which the reader keeps with a warning. Each record is
//! diagnosed; asserted: no panic, a report is produced (no error), its verdict is one of
//! the defined ones (`none`, `unknown`, a library effect, read back from report.json),
//! report.json round-trips and report.md is written.
//!
//! `PARAGYRO_TOTAL_RECORDS` (default [`RECORDS`]) and `PARAGYRO_TOTAL_SEED` (default
//! [`SEED`]) override the count and the seed (a longer local sweep). A failing case prints
//! its seed, index and protocol; every case is run before the test fails.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use paragyro_diagnose::blind::device::DeviceDraw;
use paragyro_diagnose::blind::outside::Outside;
use paragyro_diagnose::blind::size_range;
use paragyro_diagnose::diagnose::{
    Answer, Options, Report, diagnose, to_json_sorted, write_report,
};
use paragyro_simulator::effects::{Effect, EffectSpec, LIBRARY};
use paragyro_simulator::record::{RecordOptions, simulate_record_ext};
use paragyro_simulator::scenario::Scenario;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;

/// Records in CI (issue 31 asks for at least 60).
const RECORDS: usize = 60;
/// The seed of the draw in CI.
const SEED: u64 = 31;
/// Record lengths drawn, s (short: CI's time; the diagnosis needs 2 s).
const LENGTH_S: (f64, f64) = (4.0, 6.0);

/// One drawn protocol, device and effects.
#[derive(Debug)]
struct Case {
    toml: String,
    device: DeviceDraw,
    rate_dps: f64,
    reversal: Option<(f64, f64)>,
    rate_table: bool,
    temp: Option<(f64, f64)>,
    effects: Vec<EffectSpec>,
    outside: Option<(Outside, f64)>,
    seed: u64,
    /// Rows made non-finite (the reader keeps them, with a warning): first row as a share
    /// of the record, count, and which column (0–13: the data columns; 14: temp_c, 15:
    /// rate_ref_dps).
    corrupt: Option<(f64, usize, usize)>,
}

fn log_uniform(rng: &mut Xoshiro256PlusPlus, low: f64, high: f64) -> f64 {
    (low.ln() + rng.random::<f64>() * (high.ln() - low.ln())).exp()
}

fn draw_effect(rng: &mut Xoshiro256PlusPlus, e: Effect) -> EffectSpec {
    let r = size_range(e);
    let mut size = log_uniform(rng, r.low, 10.0 * r.high);
    if r.signed && rng.random::<bool>() {
        size = -size;
    }
    let param = match e {
        Effect::AngularVibration => {
            let b = 0.5 + 5.0 * rng.random::<f64>();
            Some(if rng.random::<bool>() { b } else { -b })
        }
        Effect::ElectrostaticSoftening => Some(if rng.random::<bool>() { 1.0 } else { 0.0 }),
        _ => None,
    };
    EffectSpec {
        effect: e,
        size,
        param,
    }
}

fn draw(rng: &mut Xoshiro256PlusPlus) -> Case {
    let duration = LENGTH_S.0 + (LENGTH_S.1 - LENGTH_S.0) * rng.random::<f64>();
    let dither_freq = 2.0 + 4.0 * rng.random::<f64>();
    let dither_pump = 8.0 + 24.0 * rng.random::<f64>();
    let scale_frac = 0.15 * rng.random::<f64>();
    let scale_freq = 0.5 + 2.0 * rng.random::<f64>();
    let dither_start = 0.3 + 0.7 * rng.random::<f64>();
    let mut events = String::new();
    // a pump-amplitude step (or none)
    if rng.random::<bool>() {
        let t = 1.0 + (duration - 2.0) * rng.random::<f64>();
        let s = 0.85 + 0.3 * rng.random::<f64>();
        events +=
            &format!("[[event]]\nt_s = {t}\nkind = \"pump_scale\"\ns = {s}\nramp_s = 0.2\n\n");
    }
    let device = DeviceDraw::draw(rng);
    // the rate: the device's, sometimes near zero; a reversal through a short ramp
    let rate_dps = if rng.random::<f64>() < 0.2 {
        device.rate_dps * 0.02
    } else {
        device.rate_dps
    };
    let reversal = (rng.random::<f64>() < 0.7).then(|| {
        let ramp = 0.1 + 0.5 * rng.random::<f64>();
        let t = 1.0 + (duration - 1.5 - ramp) * rng.random::<f64>();
        (t, ramp)
    });
    if let Some((t, ramp)) = reversal {
        events += &format!(
            "[[event]]\nt_s = {t}\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = {}\nduration_s = {ramp}\n\n",
            -rate_dps
        );
    }
    let toml = format!(
        "name = \"total\"\ndescription = \"issue 31 property test\"\nduration_s = {duration}\nseed = 1\n\n\
         [plant]\nwy2 = 1.0265\n\n\
         [estimator]\nforgetting = 0.999\npump_centre_hz = 21883.9526\n\
         dither_pump_hz = {dither_pump}\ndither_freq_hz = {dither_freq}\n\
         dither_scale_frac = {scale_frac}\ndither_scale_freq_hz = {scale_freq}\n\
         dither_start_s = {dither_start}\ngate_startup_s = 0.5\nretune = true\n\n{events}"
    );
    let rate_table = rng.random::<f64>() < 0.75;
    let temp = (rng.random::<f64>() < 0.6)
        .then(|| (20.0 + 10.0 * rng.random::<f64>(), 8.0 * rng.random::<f64>()));
    let u: f64 = rng.random();
    let pick = |rng: &mut Xoshiro256PlusPlus| LIBRARY[rng.random_range(0..LIBRARY.len())];
    let (effects, outside) = if u < 0.2 {
        (Vec::new(), None)
    } else if u < 0.6 {
        let e = pick(rng);
        (vec![draw_effect(rng, e)], None)
    } else if u < 0.8 {
        let a = pick(rng);
        let mut b = pick(rng);
        while b == a {
            b = pick(rng);
        }
        (vec![draw_effect(rng, a), draw_effect(rng, b)], None)
    } else {
        let kind = Outside::ALL[rng.random_range(0..Outside::ALL.len())];
        let r = kind.size_range();
        let mut size = log_uniform(rng, r.low, 10.0 * r.high);
        if r.signed && rng.random::<bool>() {
            size = -size;
        }
        (Vec::new(), Some((kind, size)))
    };
    Case {
        toml,
        device,
        rate_dps,
        reversal,
        rate_table,
        temp,
        effects,
        outside,
        seed: rng.random::<u32>() as u64,
        corrupt: (rng.random::<f64>() < 0.25).then(|| {
            (
                rng.random::<f64>(),
                [1, 3, 40, 400][rng.random_range(0..4)],
                rng.random_range(0..16),
            )
        }),
    }
}

/// What one case came to.
enum Outcome {
    /// Diagnosed: the verdict and the limitations.
    Report(Answer, Vec<String>),
    /// The simulator could not make the record (not the diagnosis's failure).
    NoRecord(String),
}

/// The paths of the nulls in `v` (a number that was not finite, written as null).
fn nulls(v: &serde_json::Value, path: &str, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Null => out.push(path.into()),
        serde_json::Value::Array(a) => a
            .iter()
            .enumerate()
            .for_each(|(i, x)| nulls(x, &format!("{path}[{i}]"), out)),
        serde_json::Value::Object(o) => o
            .iter()
            .for_each(|(k, x)| nulls(x, &format!("{path}.{k}"), out)),
        _ => {}
    }
}

/// A case run: its index, what it came to, its wall time (s).
type Done = (usize, Result<Outcome, String>, f64);

fn run(case: &Case) -> Result<Outcome, String> {
    let sc =
        Scenario::from_toml_str(&case.toml, "total.rs").map_err(|e| format!("scenario: {e}"))?;
    let mut dev = case.device.clone();
    dev.rate_dps = case.rate_dps;
    let sc = dev.apply(&sc);
    let opts = RecordOptions {
        seed: Some(case.seed),
        effects: case.effects.clone(),
        rate_table: case.rate_table,
        temp: case.temp,
    };
    let hook = case
        .outside
        .map(|(k, size)| k.hook(size, dev.physical(&sc).wy2, sc.omega0_rad_s()));
    let rec = match simulate_record_ext(&sc, &opts, hook, &mut |_| {}) {
        Ok((rec, _)) => rec,
        Err(e) => return Ok(Outcome::NoRecord(format!("{e:#}"))),
    };
    let mut rec = rec;
    if let Some((at, len, col)) = case.corrupt {
        let n = rec.rows.len();
        let k0 = ((at * n as f64) as usize).min(n - 1);
        for (j, r) in rec.rows[k0..(k0 + len).min(n)].iter_mut().enumerate() {
            let bad = if j % 2 == 0 { f64::NAN } else { f64::INFINITY };
            match col {
                0 => r.pump_hz = bad,
                1 => r.pump_amp_v = bad,
                2 => r.ax_mps2 = bad,
                3 => r.ay_mps2 = bad,
                4 => r.lockin.x0_um = bad,
                5 => r.lockin.x_um[0].re = bad,
                6 => r.lockin.x_um[0].im = bad,
                7 => r.lockin.x_um[1].re = bad,
                8 => r.lockin.x_um[2].im = bad,
                9 => r.lockin.y0_um = bad,
                10 => r.lockin.y_um[0].re = bad,
                11 => r.lockin.y_um[0].im = bad,
                12 => r.lockin.y_um[1].im = bad,
                13 => r.lockin.y_um[2].re = bad,
                14 => r.temp_c = Some(bad),
                _ => r.rate_ref_dps = None,
            }
        }
    }
    let d = diagnose(&rec, &Options::default()).map_err(|e| format!("no report: {e:#}"))?;
    let json = to_json_sorted(&d.report).map_err(|e| format!("report.json: {e}"))?;
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let back: Report = serde_json::from_str(&json).map_err(|e| {
        let mut at = Vec::new();
        nulls(&v, "", &mut at);
        format!("report.json read back: {e} (null at {at:?})")
    })?;
    let verdict = v["verdict"].as_str().ok_or("no verdict key")?;
    let answer: Answer = verdict
        .parse()
        .map_err(|e| format!("verdict '{verdict}': {e}"))?;
    if answer != d.report.verdict.answer() || back.verdict.answer() != answer {
        return Err(format!("verdict '{verdict}' does not read back"));
    }
    let md = d.report.markdown("total.csv");
    if !md.contains(&format!("**Verdict: `{answer}`**")) {
        return Err("report.md without the verdict".into());
    }
    Ok(Outcome::Report(
        answer,
        d.report
            .limitations
            .iter()
            .map(|l| format!("{}: {}", l.stage, l.detail))
            .collect(),
    ))
}

#[test]
fn the_diagnosis_is_total_over_generated_records() {
    let n: usize = std::env::var("PARAGYRO_TOTAL_RECORDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(RECORDS);
    let seed: u64 = std::env::var("PARAGYRO_TOTAL_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(SEED);
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let cases: Vec<Case> = (0..n).map(|_| draw(&mut rng)).collect();
    // `PARAGYRO_TOTAL_ONLY=i`: case i alone (a failing case again)
    let only: Option<usize> = std::env::var("PARAGYRO_TOTAL_ONLY")
        .ok()
        .and_then(|v| v.parse().ok());
    let wall = Instant::now();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Done>> = Mutex::new(Vec::new());
    // the panic hook stays quiet while a case runs (its message is collected below)
    let threads = std::thread::available_parallelism()
        .map_or(2, |v| v.get())
        .min(4);
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    if i >= n {
                        break;
                    }
                    if only.is_some_and(|o| o != i) {
                        continue;
                    }
                    let t0 = Instant::now();
                    let r = catch_unwind(AssertUnwindSafe(|| run(&cases[i]))).unwrap_or_else(|p| {
                        let msg = p
                            .downcast_ref::<String>()
                            .cloned()
                            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                            .unwrap_or_default();
                        Err(format!("panicked: {msg}"))
                    });
                    results
                        .lock()
                        .unwrap()
                        .push((i, r, t0.elapsed().as_secs_f64()));
                }
            });
        }
    });
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|r| r.0);
    let mut failures = Vec::new();
    let mut tally = std::collections::BTreeMap::<String, usize>::new();
    let (mut no_record, mut limited) = (0, 0);
    for (i, r, secs) in &results {
        let c = &cases[*i];
        match r {
            Ok(Outcome::Report(a, l)) => {
                *tally.entry(a.to_string()).or_default() += 1;
                if !l.is_empty() {
                    limited += 1;
                }
                println!(
                    "{i:3} {secs:5.1} s {a:24} | effects {:?} outside {:?} rate {:+.1} °/s reversal {:?} table {} temp {:?} corrupt {:?} | limitations {}",
                    c.effects.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
                    c.outside.map(|(k, s)| (k.name(), s)),
                    c.rate_dps,
                    c.reversal,
                    c.rate_table,
                    c.temp,
                    c.corrupt,
                    l.len()
                );
                for x in l {
                    println!("      limitation {x}");
                }
            }
            Ok(Outcome::NoRecord(e)) => {
                no_record += 1;
                println!("{i:3} no record (the simulator's: {e})");
            }
            Err(e) => failures.push(format!("seed {seed} case {i}: {e}\n  {c:?}")),
        }
    }
    println!(
        "{n} records (seed {seed}) in {:.1} s on {threads} threads: verdicts {tally:?}, {limited} with limitations, {no_record} the simulator could not make",
        wall.elapsed().as_secs_f64()
    );
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // the simulator makes most of them: the property is tested
    assert!(
        no_record * 4 <= results.len(),
        "{no_record} of {} records not made",
        results.len()
    );
}

/// Issue 31's second failure, found by the draw above (case 25 of seed 31 before the
/// non-finite rows were added to the draw) (a spurious mode at
/// 7.2e-3 on a toleranced device, a rate table reversing −4.5 → +4.5 °/s through a 0.45 s
/// ramp, 4.3 s): the calibration's first fit estimates μy < 0, and the model went to the core
/// ("core configuration: invalid configuration field `nominal.mu_y`: must be finite and
/// \> 0") with no report written. Now the configured model is kept for that step, the second
/// step's (again not physical) is not taken, the confirmation's candidate whose joint model
/// is not physical is not re-simulated, each a named limitation, and the report is written.
#[test]
fn a_calibration_that_is_not_physical_is_a_limitation_not_an_abort() {
    let toml = "name = \"total\"\ndescription = \"issue 31\"\nduration_s = 4.260188063563026\nseed = 1\n\n\
        [plant]\nwy2 = 1.0265\n\n\
        [estimator]\nforgetting = 0.999\npump_centre_hz = 21883.9526\ndither_pump_hz = 24.263043874146177\n\
        dither_freq_hz = 2.7396973467358476\ndither_scale_frac = 0.13212781573541268\n\
        dither_scale_freq_hz = 2.004296268596399\ndither_start_s = 0.3087910306520779\n\
        gate_startup_s = 0.5\nretune = true\n\n\
        [[event]]\nt_s = 2.739190261407116\nkind = \"pump_scale\"\ns = 1.0272802724878833\nramp_s = 0.2\n\n\
        [[event]]\nt_s = 2.8628251392388684\nkind = \"ramp\"\nparam = \"rate_dps\"\nto = 4.482556146432402\n\
        duration_s = 0.45077109051104114\n";
    let case = Case {
        toml: toml.into(),
        device: DeviceDraw {
            deviations: [
                0.05574751458677654,
                -0.07740365499809783,
                0.2456393227375614,
                -0.000755527163270406,
                0.0003318356871379855,
                -0.21248875750327434,
                0.07023146788386658,
                0.029870204226404164,
                -0.011315897932737719,
                -0.015548085499934595,
            ],
            rate_dps: -224.12780732162008,
            accel_mps2: [62.12345617114538, 34.302633948296005],
            noise_pm_rthz: 0.9399266597183378,
        },
        rate_dps: -4.482556146432402,
        reversal: Some((2.8628251392388684, 0.45077109051104114)),
        rate_table: true,
        temp: None,
        effects: Vec::new(),
        outside: Some((Outside::SpuriousMode, 0.007208167238009799)),
        seed: 1615313406,
        corrupt: None,
    };
    let (answer, limits) = match run(&case) {
        Ok(Outcome::Report(a, l)) => (a, l),
        Ok(Outcome::NoRecord(e)) => panic!("no record: {e}"),
        Err(e) => panic!("{e}"),
    };
    println!("{answer}: {limits:#?}");
    assert!(
        limits
            .iter()
            .any(|l| l.starts_with("calibration: the first fit") && l.contains("not physical")),
        "{limits:?}"
    );
    // an out-of-library effect: no library effect is named
    assert_eq!(answer, Answer::Unknown);
}

/// A record no stage can take still gets a report (issue 31: total over the records the
/// reader accepts): 1.5 s of record (the diagnosis needs 2 s), and 4 s whose lock-in
/// channels are all zero (the drive dead: no usable rows). Verdict `unknown`, the reason
/// the one limitation, and report.json, report.md and the plots are written.
#[test]
fn a_record_no_stage_can_take_gets_an_unknown_report_with_the_reason() {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = 4.0;
    let opts = RecordOptions {
        seed: Some(5),
        rate_table: true,
        ..RecordOptions::default()
    };
    let (rec, _) = simulate_record_ext(&sc, &opts, None, &mut |_| {}).unwrap();
    let mut short = rec.clone();
    short.rows.truncate(750);
    let mut dead = rec.clone();
    for r in &mut dead.rows {
        r.lockin = Default::default();
    }
    for (what, rec, reason) in [
        ("short", &short, "needs at least 2 s"),
        ("dead", &dead, "usable samples"),
    ] {
        let d = diagnose(rec, &Options::default()).unwrap();
        let r = &d.report;
        assert_eq!(r.verdict.answer(), Answer::Unknown, "{what}");
        assert_eq!(r.limitations.len(), 1, "{what}: {:?}", r.limitations);
        assert_eq!(r.limitations[0].stage, "record");
        assert!(
            r.limitations[0].detail.contains(reason),
            "{what}: {:?}",
            r.limitations
        );
        let dir =
            std::env::temp_dir().join(format!("paragyro-total-{what}-{}", std::process::id()));
        let files = write_report(&dir, &d, "rec.csv").unwrap();
        let back: Report =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(&back, r);
        assert!(files.len() >= 3, "{files:?}");
        std::fs::remove_dir_all(&dir).ok();
    }
}

/// Rows the reader keeps with a non-finite value (NaN, ∞: it warns) are not usable rows;
/// nothing after them is poisoned (the phase, the columns' filters, the re-simulation's
/// start, the output error, the terciles): a record with such rows reads as the same record
/// without them. Found by the draw above (a single NaN in y0 at 78 % of the record: NaN held-out
/// energies, the catch-all's and the output error's, and a report.json that could not be read
/// back, its numbers written as null).
#[test]
fn rows_with_non_finite_values_are_left_out_not_propagated() {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = 6.0;
    let opts = RecordOptions {
        seed: Some(27),
        effects: vec!["nonlinear_damping=6e-6".parse().unwrap()],
        rate_table: true,
        temp: Some((25.0, 1.0)),
    };
    let (rec, _) = simulate_record_ext(&sc, &opts, None, &mut |_| {}).unwrap();
    let clean = diagnose(&rec, &Options::default()).unwrap().report;
    let mut bad = rec.clone();
    let n = bad.rows.len();
    bad.rows[n * 78 / 100].lockin.y0_um = f64::NAN;
    for r in &mut bad.rows[n / 3..n / 3 + 40] {
        r.pump_hz = f64::INFINITY;
    }
    bad.rows[n / 2].temp_c = Some(f64::NAN);
    let d = diagnose(&bad, &Options::default()).unwrap();
    let json = to_json_sorted(&d.report).unwrap();
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back.verdict, d.report.verdict);
    assert_eq!(
        d.report.verdict, clean.verdict,
        "{:?}",
        d.report.limitations
    );
    assert!(
        d.report
            .output_error
            .as_ref()
            .is_some_and(|o| o.after.combined.is_finite()),
        "{:?}",
        d.report.output_error
    );
}

/// A finite value the reader keeps but no device gives (a lock-in channel scaled by 8.6e183
/// over 300 samples, the fuzz target `diagnosis`'s first find): its squares overflowed the
/// catch-all's Gram sums, the held-out energy went NaN and report.json held `null`, which
/// does not read back. Such samples are left out (`ROW_MAX`), with a limitation that counts
/// them.
#[test]
fn a_huge_finite_value_is_left_out_with_a_limitation_not_a_nan_report() {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = 4.0;
    let opts = RecordOptions {
        seed: Some(31),
        effects: Vec::new(),
        rate_table: true,
        temp: Some((25.0, 1.0)),
    };
    let (mut rec, _) = simulate_record_ext(&sc, &opts, None, &mut |_| {}).unwrap();
    for r in &mut rec.rows[600..900] {
        r.lockin.x_um[0].re *= 8.6e183;
    }
    let no_resim = Options {
        resimulate: false,
        confirm_runs: Some(0),
        ..Options::default()
    };
    let d = diagnose(&rec, &no_resim).unwrap();
    let e = &d.report.energies;
    assert!(
        [e.baseline, e.catch_all, e.floor, e.after]
            .iter()
            .all(|v| v.is_finite()),
        "{e:?}"
    );
    let json = to_json_sorted(&d.report).unwrap();
    let back: Report = serde_json::from_str(&json).unwrap();
    assert_eq!(back.verdict, d.report.verdict);
    assert!(
        d.report
            .limitations
            .iter()
            .any(|l| l.stage == "rows" && l.detail.contains("beyond 1e30")),
        "{:?}",
        d.report.limitations
    );
}
