//! The blind benchmark of the diagnosis (`paragyro-sim blind`): records whose effect is
//! withheld, labels sealed before any diagnosis runs, then scored.
//!
//! 1. **Draw** N records of the `characterise` scenario from the seed: 20 % clean, 50 % one
//!    library effect, 15 % two library effects, 15 % one effect outside the library. Sizes
//!    are log-uniform over [`size_range`] (which reach below the stated detection limits),
//!    signs random where the effect has both, the angular-vibration beat uniform in
//!    ±[0.5, 5] Hz; the electrostatic softening is the pump-driven one (`@1`). Every device
//!    is Table 2 off by its manufacturing tolerances ([`device::DeviceDraw`]: μ ±10 %,
//!    ω² ±0.2 %, couplings ±30 %, cubic stiffness ±10 %, β ±5 %, the pump centred on its
//!    resonance), with its own rate (±30–300 °/s), accelerations (0–10 g) and noise
//!    (0.7–1.5 pm/√Hz). Every record has a rate table (`rate_ref_dps`) and a die temperature
//!    rising by a random 2–8 K, so neither column gives the label away.
//! 2. **Seal**: all records are written, then `labels.json`, before the first diagnosis.
//! 3. **Diagnose** each record from its CSV alone ([`crate::diagnose::diagnose`]), in
//!    parallel.
//! 4. **Score** (labels read only now): confusion matrix, top-1 accuracy on single library
//!    effects above their detection limit, `unknown` on out-of-library records, false
//!    alarms on clean ones, output-error gap closure against the oracle's (the simulator
//!    re-run with the true effects at their true sizes), detection rate against size.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Context;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::{Deserialize, Serialize};

pub mod device;
pub mod lod;
pub mod outside;
#[cfg(test)]
mod sigma_tests;
#[cfg(test)]
mod tests;

use crate::diagnose::{self, Answer, Model, Options, Report, to_json_sorted};
use device::DeviceDraw;
use outside::{Outside, OutsideSpec};
use paragyro_simulator::effects::{Effect, EffectSpec, LIBRARY};
use paragyro_simulator::par;
use paragyro_simulator::record::{self, RecordOptions};
use paragyro_simulator::scenario::Scenario;

/// The size range drawn for an effect (log-uniform magnitude) and its stated detection
/// limit (the size above which the diagnosis is claimed to name it), fixed before the
/// scored run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SizeRange {
    /// Smallest magnitude drawn.
    pub low: f64,
    /// Largest magnitude drawn.
    pub high: f64,
    /// The detection limit.
    pub limit: f64,
    /// Whether both signs are drawn.
    pub signed: bool,
}

pub(crate) const fn r(low: f64, high: f64, limit: f64, signed: bool) -> SizeRange {
    SizeRange {
        low,
        high,
        limit,
        signed,
    }
}

/// The size range of each effect.
pub const fn size_range(e: Effect) -> SizeRange {
    match e {
        Effect::GeometricNonlinearity => r(1e-9, 1e-5, 1e-7, true),
        Effect::AngularVibration => r(1.0, 60.0, 20.0, false),
        Effect::ElectrostaticSoftening => r(1e-9, 1e-5, 1e-7, false),
        Effect::Feedthrough => r(1e-6, 1e-2, 1e-4, true),
        Effect::NonlinearDamping => r(1e-9, 1e-5, 1e-7, false),
        Effect::Anisodamping => r(1e-9, 1e-5, 1e-7, true),
        Effect::ForceLeak => r(1e-7, 1e-3, 1e-5, true),
        Effect::ThermalDrift => r(0.05, 50.0, 1.0, false),
        Effect::LockinMismatch => r(1e-5, 1e-1, 1e-3, true),
        Effect::QuadraticStiffness => r(1e-7, 1e-4, 1e-6, true),
        Effect::ReadoutGain => r(1e-5, 3e-2, 1e-3, true),
    }
}

/// What a drawn record holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Category {
    /// Nothing added.
    None,
    /// One library effect.
    Single,
    /// Two library effects.
    Double,
    /// One effect outside the library.
    Outside,
}

impl fmt::Display for Category {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Category::None => "none",
            Category::Single => "single",
            Category::Double => "double",
            Category::Outside => "outside",
        })
    }
}

/// One drawn record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Draw {
    /// Record id.
    pub id: String,
    /// What it holds.
    pub category: Category,
    /// Effects with their true sizes.
    pub effects: Vec<EffectSpec>,
    /// Noise seed.
    pub seed: u64,
    /// Temperature rise, K.
    pub temp_rise_k: f64,
    /// The device: Table 2 off by its tolerances, its rate, accelerations and noise.
    pub device: DeviceDraw,
    /// The out-of-library effect ([`outside`], added through the plant hook), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outside: Option<OutsideSpec>,
}

/// labels.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Labels {
    /// The seed of the draw.
    pub seed: u64,
    /// The records' labels.
    pub records: Vec<Draw>,
}

/// A log-uniform magnitude in `r`, with a random sign when `r.signed`.
fn draw_size(rng: &mut Xoshiro256PlusPlus, r: SizeRange) -> f64 {
    let size = (r.low.ln() + rng.random::<f64>() * (r.high.ln() - r.low.ln())).exp();
    if r.signed && rng.random::<bool>() {
        -size
    } else {
        size
    }
}

fn draw_effect(rng: &mut Xoshiro256PlusPlus, e: Effect) -> EffectSpec {
    let r = size_range(e);
    let mut size = (r.low.ln() + rng.random::<f64>() * (r.high.ln() - r.low.ln())).exp();
    if e == Effect::ThermalDrift || (r.signed && rng.random::<bool>()) {
        size = -size; // TCF is negative in silicon
    }
    let param = match e {
        Effect::AngularVibration => {
            let b = 0.5 + 4.5 * rng.random::<f64>();
            let b = (b * 100.0).round() / 100.0;
            Some(if rng.random::<bool>() { b } else { -b })
        }
        // the softening whose electrodes carry the pump: the record's pump-amplitude steps
        // separate it from a tolerance of ωy² and αy (a fixed one is a tolerance to it)
        Effect::ElectrostaticSoftening => Some(1.0),
        _ => None,
    };
    EffectSpec {
        effect: e,
        size,
        param,
    }
}

/// The shares of the draw (cumulative): clean, one library effect, two, out of library.
/// 20 % clean, 45 % one, 10 % two, 25 % out of library (the module [`outside`], through
/// the plant hook).
pub const SHARES: [f64; 3] = [0.20, 0.65, 0.75];

/// Draws the N records' labels from `seed`.
pub fn draw(n: usize, seed: u64) -> Vec<Draw> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x5eed_b11d);
    (0..n)
        .map(|i| {
            let u: f64 = rng.random();
            let pick_lib =
                |rng: &mut Xoshiro256PlusPlus| LIBRARY[rng.random_range(0..LIBRARY.len())];
            let mut outside = None;
            let (category, effects) = if u < SHARES[0] {
                (Category::None, Vec::new())
            } else if u < SHARES[1] {
                let e = pick_lib(&mut rng);
                (Category::Single, vec![draw_effect(&mut rng, e)])
            } else if u < SHARES[2] {
                let a = pick_lib(&mut rng);
                let mut b = pick_lib(&mut rng);
                while b == a {
                    b = pick_lib(&mut rng);
                }
                (
                    Category::Double,
                    vec![draw_effect(&mut rng, a), draw_effect(&mut rng, b)],
                )
            } else {
                let kind = Outside::ALL[rng.random_range(0..Outside::ALL.len())];
                outside = Some(OutsideSpec {
                    kind,
                    size: draw_size(&mut rng, kind.size_range()),
                });
                (Category::Outside, Vec::new())
            };
            Draw {
                id: format!("rec-{i:03}"),
                category,
                effects,
                seed: rng.random::<u32>() as u64,
                temp_rise_k: ((2.0 + 6.0 * rng.random::<f64>()) * 100.0).round() / 100.0,
                device: DeviceDraw::draw(&mut rng),
                outside,
            }
        })
        .collect()
}

impl Draw {
    /// The plant hook of its out-of-library effect, on its device.
    pub fn hook(&self, sc: &Scenario) -> Option<paragyro_simulator::plant::hook::PlantHook> {
        self.outside.map(|o| {
            o.kind
                .hook(o.size, self.device.physical(sc).wy2, sc.omega0_rad_s())
        })
    }

    /// Simulates this record on `sc` (its device, effects, noise seed, rate table and die
    /// warming, its out-of-library effect through the hook) and writes it to `path`, its
    /// truth beside it.
    pub fn write_record(&self, sc: &Scenario, path: &Path) -> anyhow::Result<record::RecordFiles> {
        let opts = RecordOptions {
            seed: Some(self.seed),
            effects: self.effects.clone(),
            rate_table: true,
            temp: Some((25.0, self.temp_rise_k)),
        };
        record::write_simulated_record_ext(
            &self.device.apply(sc),
            path,
            &opts,
            self.hook(sc),
            &mut |_| {},
        )
        .map(|(files, _)| files)
        .with_context(|| format!("recording {}", self.id))
    }

    /// The largest |size| / detection limit of its effects.
    pub fn size_over_limit(&self) -> f64 {
        let lib = self
            .effects
            .iter()
            .map(|e| e.size.abs() / size_range(e.effect).limit);
        let out = self
            .outside
            .iter()
            .map(|o| o.size.abs() / o.kind.size_range().limit);
        lib.chain(out).fold(0.0f64, f64::max)
    }
}

/// One scored record (score.json's `records`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scored {
    /// Record id.
    pub id: String,
    /// What it holds.
    pub category: Category,
    /// The true effects.
    pub truth: Vec<Effect>,
    /// The out-of-library effect, if any (its size is in `sizes`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outside: Option<Outside>,
    /// Their sizes.
    pub sizes: Vec<f64>,
    /// The diagnosis's answer.
    pub verdict: Answer,
    /// Its second effect, if any.
    pub secondary: Option<Effect>,
    /// Whether the answer is right for the category.
    pub correct: bool,
    /// Whether the largest effect is above its detection limit.
    pub above_limit: bool,
    /// The largest |size| / detection limit.
    pub size_over_limit: f64,
    /// The diagnosis's output-error closure.
    pub oe_closure: Option<f64>,
    /// The oracle's (true effects at their true sizes).
    pub oracle_closure: Option<f64>,
    /// The verdict's fitted size.
    pub fitted_size: Option<f64>,
    /// Clean records: device parameters within the diagnosis's 1σ, of how many.
    pub parameters_covered: Option<(usize, usize)>,
    /// Wall time of the diagnosis, s.
    pub seconds: f64,
}

/// Runs the benchmark into `dir` (records/, labels.json, diagnoses/, score.json, score.md).
/// `progress` gets messages (from the worker threads).
pub fn run(
    n: usize,
    seed: u64,
    dir: &Path,
    progress: &(dyn Fn(&str) + Sync),
) -> anyhow::Result<Summary> {
    let sc = Scenario::load("characterise").map_err(anyhow::Error::new)?;
    let draws = draw(n, seed);
    let rec_dir = dir.join("records");
    std::fs::create_dir_all(&rec_dir)
        .with_context(|| format!("cannot create {}", rec_dir.display()))?;

    // 1. records, 2. the sealed labels
    let t0 = Instant::now();
    let paths: Vec<PathBuf> = draws
        .iter()
        .map(|d| rec_dir.join(format!("{}.csv", d.id)))
        .collect();
    let jobs: Vec<(&Draw, &PathBuf)> = draws.iter().zip(&paths).collect();
    par::try_map(
        &jobs,
        |(d, _)| format!("recording {}", d.id),
        |(d, p)| d.write_record(&sc, p).map(|_| ()),
    )?;
    progress(&format!(
        "wrote {n} records in {:.0} s",
        t0.elapsed().as_secs_f64()
    ));
    let labels = dir.join("labels.json");
    std::fs::write(
        &labels,
        to_json_sorted(&Labels {
            seed,
            records: draws.clone(),
        })?,
    )
    .with_context(|| format!("cannot write {}", labels.display()))?;
    progress(&format!("sealed the labels in {}", labels.display()));

    // 3. diagnoses, from the CSV alone
    let reports = diagnose_all(&paths, &draws, &dir.join("diagnoses"), progress)?;

    // 4. score (labels used from here on)
    let ix: Vec<usize> = (0..n).collect();
    let scored = par::try_map(
        &ix,
        |&i| format!("scoring {}", draws[i].id),
        |&i| score(&draws[i], &paths[i], &reports[i], &sc),
    )?;
    let summary = summarize(&scored, n, seed);
    std::fs::write(
        dir.join("score.json"),
        to_json_sorted(&Score {
            summary: &summary,
            records: &scored,
        })?,
    )?;
    std::fs::write(dir.join("score.md"), markdown(&summary, &scored))?;
    Ok(summary)
}

/// Diagnoses every record (in parallel, at most as many at once as there are threads, so
/// the memory stays bounded), writes each report.json, and returns the reports in order.
fn diagnose_all(
    paths: &[PathBuf],
    draws: &[Draw],
    diag_dir: &Path,
    progress: &(dyn Fn(&str) + Sync),
) -> anyhow::Result<Vec<Report>> {
    let n = paths.len();
    let done = AtomicUsize::new(0);
    let items: Vec<(usize, &PathBuf)> = paths.iter().enumerate().collect();
    let mut reports = Vec::with_capacity(n);
    for chunk in items.chunks(rayon::current_num_threads().max(1)) {
        reports.extend(par::try_map(
            chunk,
            |(_, p)| format!("diagnosing {}", p.display()),
            |&(i, p)| {
                let rec = record::read_record(p).map_err(anyhow::Error::new)?;
                let d = diagnose::diagnose(&rec, &Options::default())
                    .with_context(|| format!("diagnosing {}", p.display()))?;
                let out = diag_dir.join(&draws[i].id);
                std::fs::create_dir_all(&out)
                    .with_context(|| format!("cannot create {}", out.display()))?;
                std::fs::write(out.join("report.json"), to_json_sorted(&d.report)?)?;
                let k = done.fetch_add(1, Ordering::Relaxed) + 1;
                progress(&format!("[{k}/{n}] {} → {}", draws[i].id, d.report.verdict));
                Ok(d.report)
            },
        )?);
    }
    Ok(reports)
}

/// Whether `verdict` is right for a record of `category` holding `truth`.
pub fn correct_for(category: Category, truth: &[Effect], verdict: Answer) -> bool {
    match category {
        Category::None => verdict == Answer::None,
        Category::Outside => verdict == Answer::Unknown,
        Category::Single | Category::Double => {
            matches!(verdict, Answer::Effect(e) if truth.contains(&e))
        }
    }
}

/// The ten device parameters (mu_x … beta3) of a clean record: how many the diagnosis's
/// 1σ interval covers, of how many.
fn coverage(d: &Draw, r: &Report, sc: &Scenario) -> Option<(usize, usize)> {
    if d.category != Category::None {
        return None;
    }
    let truth = d.device.physical(sc).as_array();
    let names = paragyro_core::physics::PHYSICAL_NAMES;
    let mut n = (0, 0);
    for (i, name) in names.iter().enumerate().take(10) {
        let p = r
            .parameter_face
            .parameters
            .iter()
            .find(|p| p.name == *name)?;
        n.1 += 1;
        if (p.device - truth[i]).abs() <= p.sigma {
            n.0 += 1;
        }
    }
    Some(n)
}

/// A record's score against its label.
fn score(d: &Draw, path: &Path, r: &Report, sc: &Scenario) -> anyhow::Result<Scored> {
    let verdict = r.verdict.answer();
    let truth: Vec<Effect> = d.effects.iter().map(|e| e.effect).collect();
    let correct = correct_for(d.category, &truth, verdict);
    let ratio = d.size_over_limit();
    // the oracle: the simulator with the true effects at their true sizes, same span
    let oracle_closure = match d.category {
        Category::Single | Category::Double => {
            let rec = record::read_record(path).map_err(anyhow::Error::new)?;
            oracle(&rec, r, &d.effects, &d.device.physical(sc)).ok()
        }
        Category::None | Category::Outside => None,
    };
    let fitted_size = match verdict {
        Answer::Effect(e) => r
            .ranking
            .iter()
            .find(|c| c.effect == e)
            .and_then(|c| c.size),
        Answer::None | Answer::Unknown => None,
    };
    Ok(Scored {
        id: d.id.clone(),
        category: d.category,
        sizes: d
            .effects
            .iter()
            .map(|e| e.size)
            .chain(d.outside.map(|o| o.size))
            .collect(),
        outside: d.outside.map(|o| o.kind),
        verdict,
        secondary: r.verdict.secondary().map(|s| s.effect),
        correct,
        above_limit: ratio >= 1.0,
        size_over_limit: ratio,
        oe_closure: r
            .output_error
            .as_ref()
            .map(|o| o.closure)
            .filter(|v| v.is_finite()),
        oracle_closure,
        fitted_size: fitted_size.filter(|v| v.is_finite()),
        parameters_covered: coverage(d, r, sc),
        seconds: r.seconds,
        truth,
    })
}

/// Output-error closure of the true device (its parameters) with the true effects at their
/// true sizes on the diagnosis's held-out span (the same re-simulation and error measure as
/// the diagnosis).
fn oracle(
    rec: &record::Record,
    report: &Report,
    effects: &[EffectSpec],
    device: &paragyro_core::Physical,
) -> anyhow::Result<f64> {
    let oe = report
        .output_error
        .as_ref()
        .context("no output error in the report")?;
    let before = oe.before.above_noise;
    let [t0, t1] = report.spans_s.held_out;
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
        model: &Model {
            phys: *device,
            source: "the true device".into(),
            gamma_offset: 0.0,
        },
        gamma: None,
        rate_ref: Some(&rr),
        effects,
        vib_phase0: 0.0,
        steps_per_period: 128,
    }
    .run(k0..k1)?;
    let mut full = vec![paragyro_simulator::lockin::LockinOut::default(); rec.rows.len()];
    full[k0..k1].clone_from_slice(&sim);
    let e = diagnose::output_error(rec, &full, k0..k1, oe.noise_diff_ratio);
    Ok(1.0 - e.above_noise / before.max(1e-300))
}

/// score.json.
#[derive(Serialize)]
struct Score<'a> {
    summary: &'a Summary,
    records: &'a [Scored],
}

/// The upper end of a size bin: a number or "inf".
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Bound {
    /// A finite bound.
    Finite(f64),
    /// No bound ("inf").
    Named(&'static str),
}

/// Detection against size: single library effects whose size over the detection limit is
/// in a bin.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DetectionBin {
    /// The bin [low, high) of size / detection limit.
    pub size_over_limit: (f64, Bound),
    /// Records in it.
    pub records: usize,
    /// Share named correctly.
    pub named_correctly: Option<f64>,
    /// Share answered `none`.
    pub said_none: Option<f64>,
}

/// An effect's drawn range and detection limit (score.json's `limits`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Limit {
    pub effect: Effect,
    pub low: f64,
    pub high: f64,
    pub detection_limit: f64,
}

/// The thresholds of the diagnosis that scored.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BlindThresholds {
    pub t_sig: f64,
    pub gap_min: f64,
    pub share_min: f64,
}

/// The scores (score.json's `summary`); shares are `None` when they have no record.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Summary {
    pub n: usize,
    pub seed: u64,
    /// Top-1 on single library effects above their detection limit.
    pub top1_single_above_limit: Option<f64>,
    pub single_above_limit_records: usize,
    /// `unknown` on out-of-library records.
    pub unknown_on_outside: Option<f64>,
    pub unknown_on_outside_above_limit: Option<f64>,
    pub outside_above_limit_records: usize,
    /// `unknown` on out-of-library records whose type lies outside the diagnosis's span
    /// ([`Outside::outside_span`]): all of them, and those above their detection limit
    /// (the gated share).
    pub unknown_on_outside_span: Option<f64>,
    pub outside_span_records: usize,
    pub unknown_on_outside_span_above_limit: Option<f64>,
    pub outside_span_above_limit_records: usize,
    /// Top-1 on single library effects, all sizes.
    pub top1_single_all_sizes: Option<f64>,
    /// A library effect named on an out-of-library record.
    pub false_attribution_on_outside: Option<f64>,
    pub outside_records: usize,
    /// Anything but `none` on a clean record.
    pub false_alarms_on_clean: Option<f64>,
    /// Clean records' device parameters (ten each) within the diagnosis's 1σ interval.
    pub parameter_coverage_1sigma: Option<f64>,
    pub parameter_coverage_samples: usize,
    pub clean_records: usize,
    pub double_one_named: Option<f64>,
    pub double_both_named: Option<f64>,
    pub double_records: usize,
    /// Median output-error closure over the oracle's (single, above the limit).
    pub median_closure_over_oracle: Option<f64>,
    pub median_oe_closure_single_above: Option<f64>,
    pub median_oracle_closure_single_above: Option<f64>,
    /// Truth (first effect, `none`, `outside:…`, `two effects`) → verdict → count.
    pub confusion: BTreeMap<String, BTreeMap<String, usize>>,
    pub detection_vs_size: Vec<DetectionBin>,
    pub median_diagnosis_seconds: Option<f64>,
    pub limits: Vec<Limit>,
    /// The out-of-library types' ranges and detection limits.
    pub outside_limits: Vec<OutsideLimit>,
    pub thresholds: BlindThresholds,
}

/// An out-of-library type's drawn range and detection limit (score.json's
/// `outside_limits`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OutsideLimit {
    pub kind: Outside,
    pub outside_span: bool,
    pub low: f64,
    pub high: f64,
    pub detection_limit: f64,
}

/// The median (upper middle for an even count) of the finite values.
pub fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    Some(v[v.len() / 2])
}

/// `num / den`, `None` without records.
fn frac(num: usize, den: usize) -> Option<f64> {
    (den > 0).then(|| num as f64 / den as f64)
}

/// The scores of the records `s` of a run of `n` records from `seed`.
pub fn summarize(s: &[Scored], n: usize, seed: u64) -> Summary {
    let of = |c: Category| -> Vec<&Scored> { s.iter().filter(|r| r.category == c).collect() };
    let (single, outside, clean, double) = (
        of(Category::Single),
        of(Category::Outside),
        of(Category::None),
        of(Category::Double),
    );
    let single_above: Vec<&Scored> = single.iter().copied().filter(|r| r.above_limit).collect();
    let count = |v: &[&Scored], f: &dyn Fn(&Scored) -> bool| v.iter().filter(|r| f(r)).count();
    let named = |r: &Scored| matches!(r.verdict, Answer::Effect(_));
    let ratios: Vec<f64> = single_above
        .iter()
        .filter_map(|r| match (r.oe_closure, r.oracle_closure) {
            (Some(a), Some(o)) if o > 0.0 => Some(a / o),
            _ => None,
        })
        .collect();
    let outside_above: Vec<&Scored> = outside.iter().copied().filter(|r| r.above_limit).collect();
    let span_out = |r: &&Scored| r.outside.is_some_and(|o| o.outside_span());
    let out_span: Vec<&Scored> = outside.iter().copied().filter(span_out).collect();
    let out_span_above: Vec<&Scored> = outside_above.iter().copied().filter(span_out).collect();
    let unknown = |r: &Scored| r.verdict == Answer::Unknown;
    Summary {
        n,
        seed,
        top1_single_above_limit: frac(count(&single_above, &|r| r.correct), single_above.len()),
        single_above_limit_records: single_above.len(),
        unknown_on_outside: frac(
            count(&outside, &|r| r.verdict == Answer::Unknown),
            outside.len(),
        ),
        unknown_on_outside_above_limit: frac(
            count(&outside_above, &|r| r.verdict == Answer::Unknown),
            outside_above.len(),
        ),
        outside_above_limit_records: outside_above.len(),
        unknown_on_outside_span: frac(count(&out_span, &unknown), out_span.len()),
        outside_span_records: out_span.len(),
        unknown_on_outside_span_above_limit: frac(
            count(&out_span_above, &unknown),
            out_span_above.len(),
        ),
        outside_span_above_limit_records: out_span_above.len(),
        top1_single_all_sizes: frac(count(&single, &|r| r.correct), single.len()),
        false_attribution_on_outside: frac(count(&outside, &named), outside.len()),
        outside_records: outside.len(),
        false_alarms_on_clean: frac(count(&clean, &|r| r.verdict != Answer::None), clean.len()),
        parameter_coverage_1sigma: {
            let (a, b) = s
                .iter()
                .filter_map(|r| r.parameters_covered)
                .fold((0, 0), |x, y| (x.0 + y.0, x.1 + y.1));
            frac(a, b)
        },
        parameter_coverage_samples: s
            .iter()
            .filter_map(|r| r.parameters_covered)
            .map(|c| c.1)
            .sum(),
        clean_records: clean.len(),
        double_one_named: frac(count(&double, &|r| r.correct), double.len()),
        double_both_named: frac(
            count(&double, &|r| {
                r.correct && r.secondary.is_some_and(|x| r.truth.contains(&x))
            }),
            double.len(),
        ),
        double_records: double.len(),
        median_closure_over_oracle: median(ratios),
        median_oe_closure_single_above: median(
            single_above.iter().filter_map(|r| r.oe_closure).collect(),
        ),
        median_oracle_closure_single_above: median(
            single_above
                .iter()
                .filter_map(|r| r.oracle_closure)
                .collect(),
        ),
        confusion: confusion(s),
        detection_vs_size: detection_vs_size(&single),
        median_diagnosis_seconds: median(s.iter().map(|r| r.seconds).collect()),
        limits: Effect::ALL
            .iter()
            .map(|&e| {
                let r = size_range(e);
                Limit {
                    effect: e,
                    low: r.low,
                    high: r.high,
                    detection_limit: r.limit,
                }
            })
            .collect(),
        outside_limits: Outside::ALL
            .iter()
            .map(|&kind| {
                let r = kind.size_range();
                OutsideLimit {
                    kind,
                    outside_span: kind.outside_span(),
                    low: r.low,
                    high: r.high,
                    detection_limit: r.limit,
                }
            })
            .collect(),
        thresholds: BlindThresholds {
            t_sig: diagnose::T_SIG,
            gap_min: diagnose::GAP_MIN,
            share_min: diagnose::SHARE_MIN,
        },
    }
}

/// Truth (first effect / none / outside / two effects) → verdict → count.
pub fn confusion(s: &[Scored]) -> BTreeMap<String, BTreeMap<String, usize>> {
    let mut conf: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for r in s {
        let first = r.truth.first().map_or("?", |e| e.name());
        let t = match r.category {
            Category::None => "none".to_string(),
            Category::Outside => format!("outside:{}", r.outside.map_or(first, |o| o.name())),
            Category::Double => "two effects".to_string(),
            Category::Single => first.to_string(),
        };
        *conf
            .entry(t)
            .or_default()
            .entry(r.verdict.to_string())
            .or_default() += 1;
    }
    conf
}

/// Detection rate against size (single library effects), by size / limit.
fn detection_vs_size(single: &[&Scored]) -> Vec<DetectionBin> {
    let bins = [(0.0, 0.3), (0.3, 1.0), (1.0, 10.0), (10.0, f64::INFINITY)];
    bins.iter()
        .map(|&(a, b)| {
            let v: Vec<&&Scored> = single
                .iter()
                .filter(|r| r.size_over_limit >= a && r.size_over_limit < b)
                .collect();
            DetectionBin {
                size_over_limit: (
                    a,
                    if b.is_finite() {
                        Bound::Finite(b)
                    } else {
                        Bound::Named("inf")
                    },
                ),
                records: v.len(),
                named_correctly: frac(v.iter().filter(|r| r.correct).count(), v.len()),
                said_none: frac(
                    v.iter().filter(|r| r.verdict == Answer::None).count(),
                    v.len(),
                ),
            }
        })
        .collect()
}

/// A share as "N %" ("–" without records).
fn pct(v: Option<f64>) -> String {
    v.map_or("–".into(), |x| format!("{:.0} %", 100.0 * x))
}

/// A value as JSON text (how score.md has always printed the bins' bounds).
fn json_text<T: Serialize>(v: &T) -> String {
    serde_json::to_string(v).unwrap_or_default()
}

fn markdown(sm: &Summary, s: &[Scored]) -> String {
    let mut m = format!(
        "# Blind benchmark of the diagnosis (N = {}, seed {})\n\n| measure | result | target |\n|---|---|---|\n",
        sm.n, sm.seed
    );
    let n = |label: &str, count: usize| format!("{label} ({count})");
    let rows: [(String, String, &str); 12] = [
        (
            format!(
                "top-1 on single library effects above the detection limit ({} records)",
                sm.single_above_limit_records
            ),
            pct(sm.top1_single_above_limit),
            "≥ 90 %",
        ),
        (
            n("`unknown` on out-of-library records", sm.outside_records),
            pct(sm.unknown_on_outside),
            "≥ 80 %",
        ),
        (
            n(
                "`unknown` on out-of-library records above their detection limit",
                sm.outside_above_limit_records,
            ),
            pct(sm.unknown_on_outside_above_limit),
            "",
        ),
        (
            n(
                "`unknown` on out-of-library records outside the diagnosis's span",
                sm.outside_span_records,
            ),
            pct(sm.unknown_on_outside_span),
            "",
        ),
        (
            n(
                "`unknown` on those above their detection limit",
                sm.outside_span_above_limit_records,
            ),
            pct(sm.unknown_on_outside_span_above_limit),
            "≥ 80 %",
        ),
        (
            "false attribution on out-of-library records".into(),
            pct(sm.false_attribution_on_outside),
            "",
        ),
        (
            "top-1 on single library effects, all sizes (`none` below the limit counts as a miss)"
                .into(),
            pct(sm.top1_single_all_sizes),
            "",
        ),
        (
            n("false alarms on clean records", sm.clean_records),
            pct(sm.false_alarms_on_clean),
            "≤ 10 %",
        ),
        (
            "median output-error gap closure / oracle closure (single, above limit)".into(),
            pct(sm.median_closure_over_oracle),
            "≥ 80 %",
        ),
        (
            format!(
                "clean devices' parameters within their 1σ ({} parameter values)",
                sm.parameter_coverage_samples
            ),
            pct(sm.parameter_coverage_1sigma),
            "60–75 %",
        ),
        (
            n("two effects: one named / both named", sm.double_records),
            format!(
                "{} / {}",
                pct(sm.double_one_named),
                pct(sm.double_both_named)
            ),
            "",
        ),
        (
            "median diagnosis time (20 s record)".into(),
            format!("{:.2} s", sm.median_diagnosis_seconds.unwrap_or(f64::NAN)),
            "",
        ),
    ];
    for (label, value, target) in rows {
        let target = if target.is_empty() {
            String::new()
        } else {
            format!(" {target}")
        };
        m.push_str(&format!("| {label} | {value} |{target} |\n"));
    }
    m.push_str("\n## Detection against size (single library effects)\n\n| size / detection limit | records | named correctly | said none |\n|---|---|---|---|\n");
    for b in &sm.detection_vs_size {
        m.push_str(&format!(
            "| {}–{} | {} | {} | {} |\n",
            json_text(&b.size_over_limit.0),
            json_text(&b.size_over_limit.1),
            b.records,
            pct(b.named_correctly),
            pct(b.said_none)
        ));
    }
    m.push_str("\n## Confusion (truth → verdict)\n\n");
    for (t, v) in &sm.confusion {
        let cells: Vec<String> = v.iter().map(|(k, n)| format!("{k}: {n}")).collect();
        m.push_str(&format!("- **{t}** → {}\n", cells.join(", ")));
    }
    m.push_str("\n## Records\n\n| id | category | truth (size) | verdict | OE closure | oracle |\n|---|---|---|---|---|---|\n");
    for r in s {
        let names: Vec<&str> = r
            .truth
            .iter()
            .map(|e| e.name())
            .chain(r.outside.map(|o| o.name()))
            .collect();
        let truth: Vec<String> = names
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
            r.secondary.map(|x| format!(" + {x}")).unwrap_or_default(),
            f(r.oe_closure),
            f(r.oracle_closure)
        ));
    }
    m
}
