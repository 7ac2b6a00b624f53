//! Detection limits measured on development devices (`cargo run --profile test -p
//! paragyro-diagnose --example lod -- K SEED DIR`): for each library effect and each
//! out-of-library type, `points` sizes log-spaced over the range the blind benchmark
//! draws ([`super::size_range`], [`Outside::size_range`]), K devices at each size drawn
//! as the benchmark draws them (tolerances, rate, accelerations, noise, temperature rise;
//! the effect's sign, beat and electrodes too), recorded and diagnosed as the benchmark
//! does. A library effect counts as detected when it is named, an out-of-library one when
//! the verdict is `unknown`. The **90 % limit** of an effect is the smallest grid size
//! from which on every larger grid size at least 90 % of the K records are detected; no
//! limit when the largest size misses.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use serde::Serialize;

use super::outside::{Outside, OutsideSpec};
use super::{Category, DeviceDraw, Draw, SizeRange, correct_for, draw_effect, size_range};
use crate::diagnose::{self, Options, to_json_sorted};
use paragyro_simulator::effects::{Effect, LIBRARY};
use paragyro_simulator::par;
use paragyro_simulator::record;
use paragyro_simulator::scenario::Scenario;

/// What a sweep targets: a library effect or an out-of-library type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Target {
    /// A library effect (detected when named).
    Library(Effect),
    /// An out-of-library type (detected when `unknown`).
    Outside(Outside),
}

impl Target {
    /// Every library effect, then every out-of-library type.
    pub fn all() -> Vec<Target> {
        LIBRARY
            .iter()
            .map(|&e| Target::Library(e))
            .chain(Outside::ALL.iter().map(|&o| Target::Outside(o)))
            .collect()
    }

    /// The name in reports (`outside:` before an out-of-library type).
    pub fn name(self) -> String {
        match self {
            Target::Library(e) => e.name().to_string(),
            Target::Outside(o) => format!("outside:{}", o.name()),
        }
    }

    /// The range the blind benchmark draws, with its stated limit.
    pub fn range(self) -> SizeRange {
        match self {
            Target::Library(e) => size_range(e),
            Target::Outside(o) => o.size_range(),
        }
    }
}

/// The sizes of a sweep: `points` log-spaced over [low, high] (both ends included).
pub fn grid(r: SizeRange, points: usize) -> Vec<f64> {
    let n = points.max(2);
    (0..n)
        .map(|i| {
            let f = i as f64 / (n - 1) as f64;
            (r.low.ln() + f * (r.high.ln() - r.low.ln())).exp()
        })
        .collect()
}

/// One size of one target: how many of its records were detected, and their verdicts.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LodRow {
    /// The target's name.
    pub target: String,
    /// The magnitude.
    pub size: f64,
    /// Records at this size.
    pub records: usize,
    /// Detected (named, or `unknown` out of the library).
    pub detected: usize,
    /// Verdict → count.
    pub verdicts: BTreeMap<String, usize>,
}

/// The 90 % limit from one target's rows (sorted by size): the smallest size from which
/// every row has at least 90 % detected; `None` when the largest size misses.
pub fn limit90(rows: &[&LodRow]) -> Option<f64> {
    let mut limit = None;
    for r in rows.iter().rev() {
        if r.records > 0 && r.detected * 10 >= r.records * 9 {
            limit = Some(r.size);
        } else {
            break;
        }
    }
    limit
}

/// The random stream of one record of a sweep: target `ti` (in the filtered list), size
/// `si`, device `j`.
fn job_rng(seed: u64, ti: usize, si: usize, j: usize) -> Xoshiro256PlusPlus {
    Xoshiro256PlusPlus::seed_from_u64(
        seed ^ 0x10d_5eed ^ ((ti as u64) << 40) ^ ((si as u64) << 20) ^ j as u64,
    )
}

/// One drawn record of a sweep: the benchmark's draw with the magnitude fixed.
fn draw_at(t: Target, size: f64, id: String, rng: &mut Xoshiro256PlusPlus) -> Draw {
    let (category, effects, outside) = match t {
        Target::Library(e) => {
            let mut spec = draw_effect(rng, e);
            spec.size = size.copysign(spec.size);
            (Category::Single, vec![spec], None)
        }
        Target::Outside(o) => {
            let signed = o.size_range().signed && rng.random::<bool>();
            let spec = OutsideSpec {
                kind: o,
                size: if signed { -size } else { size },
            };
            (Category::Outside, Vec::new(), Some(spec))
        }
    };
    Draw {
        id,
        category,
        effects,
        seed: rng.random::<u32>() as u64,
        temp_rise_k: ((2.0 + 6.0 * rng.random::<f64>()) * 100.0).round() / 100.0,
        device: DeviceDraw::draw(rng),
        outside,
    }
}

/// Runs the sweep into `dir` (lod.json, lod.md, and records/ with the records that were
/// missed, their truth beside them) and returns its rows. `only` keeps the targets whose
/// name contains it. `progress` gets a line per record.
pub fn sweep(
    k: usize,
    seed: u64,
    points: usize,
    only: Option<&str>,
    dir: &Path,
    progress: &(dyn Fn(&str) + Sync),
) -> anyhow::Result<Vec<LodRow>> {
    anyhow::ensure!(k > 0, "K must be at least 1");
    let sc = Scenario::load("characterise").map_err(anyhow::Error::new)?;
    let targets: Vec<Target> = Target::all()
        .into_iter()
        .filter(|t| only.is_none_or(|s| t.name().contains(s)))
        .collect();
    anyhow::ensure!(!targets.is_empty(), "no target matches {only:?}");
    let mut jobs = Vec::new();
    for (ti, &t) in targets.iter().enumerate() {
        for (si, &size) in grid(t.range(), points).iter().enumerate() {
            for j in 0..k {
                let mut rng = job_rng(seed, ti, si, j);
                let id = format!("{}-{si}-{j}", t.name().replace(':', "-"));
                jobs.push((t, size, draw_at(t, size, id, &mut rng)));
            }
        }
    }
    let rec_dir = dir.join("records");
    std::fs::create_dir_all(&rec_dir)
        .with_context(|| format!("cannot create {}", rec_dir.display()))?;
    let n = jobs.len();
    let done = AtomicUsize::new(0);
    let verdicts = par::try_map(
        &jobs,
        |(_, _, d)| format!("record {}", d.id),
        |(_, _, d)| {
            let path = rec_dir.join(format!("{}.csv", d.id));
            let files = d.write_record(&sc, &path)?;
            let rec = record::read_record(&path).map_err(anyhow::Error::new)?;
            let r = diagnose::diagnose(&rec, &Options::default())
                .with_context(|| format!("diagnosing {}", path.display()))?;
            let v = r.report.verdict.answer();
            // the misses stay (record and truth) to be diagnosed again; the hits go
            let truth: Vec<Effect> = d.effects.iter().map(|e| e.effect).collect();
            let hit = correct_for(d.category, &truth, v);
            if hit {
                for f in [&files.csv, &files.truth] {
                    std::fs::remove_file(f)
                        .with_context(|| format!("cannot remove {}", f.display()))?;
                }
            }
            let i = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(&format!("[{i}/{n}] {} → {v}", d.id));
            Ok((v, hit))
        },
    )?;
    let mut rows: Vec<LodRow> = Vec::new();
    for ((t, size, _), (v, hit)) in jobs.iter().zip(&verdicts) {
        let name = t.name();
        let row = match rows
            .iter_mut()
            .find(|r| r.target == name && r.size == *size)
        {
            Some(r) => r,
            None => {
                rows.push(LodRow {
                    target: name,
                    size: *size,
                    records: 0,
                    detected: 0,
                    verdicts: BTreeMap::new(),
                });
                rows.last_mut().expect("just pushed")
            }
        };
        row.records += 1;
        row.detected += usize::from(*hit);
        *row.verdicts.entry(v.to_string()).or_insert(0) += 1;
    }
    std::fs::write(dir.join("lod.json"), to_json_sorted(&rows)?)
        .with_context(|| format!("cannot write {}", dir.join("lod.json").display()))?;
    std::fs::write(dir.join("lod.md"), markdown(&targets, &rows, k, seed))?;
    Ok(rows)
}

/// lod.md: per target its stated limit, the measured 90 % limit and the detection per size.
pub fn markdown(targets: &[Target], rows: &[LodRow], k: usize, seed: u64) -> String {
    let mut s = format!(
        "# Detection limits measured (K = {k} devices per size, seed {seed})\n\n\
         | target | stated limit | measured 90 % limit | detected per size (size: detected/K, verdicts) |\n\
         |---|---|---|---|\n"
    );
    for t in targets {
        let name = t.name();
        let mine: Vec<&LodRow> = rows.iter().filter(|r| r.target == name).collect();
        let lim = limit90(&mine).map_or("not reached".to_string(), |v| format!("{v:.3e}"));
        let cells: Vec<String> = mine
            .iter()
            .map(|r| {
                let v: Vec<String> = r.verdicts.iter().map(|(k, n)| format!("{k} {n}")).collect();
                format!(
                    "{:.2e}: {}/{} ({})",
                    r.size,
                    r.detected,
                    r.records,
                    v.join(", ")
                )
            })
            .collect();
        s += &format!(
            "| {name} | {:.1e} | {lim} | {} |\n",
            t.range().limit,
            cells.join("; ")
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(size: f64, detected: usize) -> LodRow {
        LodRow {
            target: "x".into(),
            size,
            records: 10,
            detected,
            verdicts: BTreeMap::new(),
        }
    }

    /// The limit is where detection stays at or above 90 % up to the largest size, not
    /// the first size that reaches it.
    #[test]
    fn limit90_is_where_detection_stays_at_90_percent() {
        let rows = [row(1.0, 10), row(2.0, 3), row(3.0, 9), row(4.0, 10)];
        let r: Vec<&LodRow> = rows.iter().collect();
        assert_eq!(limit90(&r), Some(3.0));
        let rows = [row(1.0, 9), row(2.0, 10), row(3.0, 8)];
        let r: Vec<&LodRow> = rows.iter().collect();
        assert_eq!(limit90(&r), None);
        let rows = [row(1.0, 9), row(2.0, 10)];
        let r: Vec<&LodRow> = rows.iter().collect();
        assert_eq!(limit90(&r), Some(1.0));
    }

    /// An angular vibration at 60 °/s on a toleranced development device (`lod 6 202 DIR 2
    /// angular`, its record `angular_vibration-1-0`): found at 59.1 ± 1.5 °/s and the
    /// re-simulation with it at 1.05 × the record's noise, but with one noise level for all
    /// rows the drive's 1st-harmonic rows (≈ 1.5× and 1.3× the mean noise on clean devices)
    /// read as a gap left unexplained, and the verdict was `unknown`. With each row's own
    /// level (`NOISE_ROW_PROFILE`) and a record brought to its noise, it is named.
    #[test]
    fn a_large_angular_vibration_is_named() {
        let sc = Scenario::load("characterise").unwrap();
        let size = grid(size_range(Effect::AngularVibration), 2)[1];
        let t = Target::Library(Effect::AngularVibration);
        let d = draw_at(t, size, "av".into(), &mut job_rng(202, 0, 1, 0));
        let (answer, confirmation) = verdict_of(&sc, &d, "av");
        assert_eq!(
            answer,
            crate::diagnose::Answer::Effect(Effect::AngularVibration),
            "{confirmation}"
        );
    }

    /// Sweep seed 101's vibration at 15.3 °/s (`lod 6 101 DIR 7 angular`, its fifth size,
    /// first device): below its stated limit of 20 °/s the vibration's gap is under the 5 %
    /// of the held-out energy that a gap needs, and the record read `none`; the vibration
    /// stands far above the beat scan's chance level, off the dither lines, and is named at
    /// the noise (`verdict::vibration_at_noise`).
    #[test]
    fn a_vibration_under_the_gap_is_named_at_the_noise() {
        let sc = Scenario::load("characterise").unwrap();
        let size = grid(size_range(Effect::AngularVibration), 7)[4];
        assert!((size - 15.3).abs() < 0.1, "{size}");
        let t = Target::Library(Effect::AngularVibration);
        let d = draw_at(t, size, "av15".into(), &mut job_rng(101, 0, 4, 0));
        let (answer, confirmation) = verdict_of(&sc, &d, "av15");
        assert_eq!(
            answer,
            crate::diagnose::Answer::Effect(Effect::AngularVibration),
            "{confirmation}"
        );
    }

    /// Record 93 of the blind draw of seed 2626: an angular vibration at 36.5 °/s, 1.8×
    /// its limit, fitted at 36.3 ± 1.0 °/s and closing all the floor closes, at 1.098 × its
    /// noise. Its drive 1st-quadrature row reads 1.77 after the vibration against the
    /// floor's 1.65, more than half of that row's 0.12 "gap" left, which a rule on the whole
    /// gap reads as `unknown`; the row's own noise level is 1.78: nothing is left above it.
    /// The per-row rule counts only what is left above the row's own level by more than 3×
    /// its scatter there (`NOISE_ROW_SCATTER_OWN`), so it is named.
    #[test]
    fn a_vibration_whose_rows_are_at_their_own_noise_is_named() {
        let sc = Scenario::load("characterise").unwrap();
        let d = super::super::draw(100, 2626).swap_remove(93);
        assert_eq!(d.id, "rec-093");
        let (answer, confirmation) = verdict_of(&sc, &d, "r93");
        assert_eq!(
            answer,
            crate::diagnose::Answer::Effect(Effect::AngularVibration),
            "{confirmation}"
        );
    }

    /// The draw recorded (in a temporary directory) and diagnosed: its verdict and the
    /// confirmation's trials, printed.
    fn verdict_of(sc: &Scenario, d: &Draw, tag: &str) -> (crate::diagnose::Answer, String) {
        let dir = std::env::temp_dir().join(format!("paragyro-lod-{tag}-{}", std::process::id()));
        let path = dir.join(format!("{tag}.csv"));
        d.write_record(sc, &path).unwrap();
        let rec = record::read_record(&path).unwrap();
        let r = diagnose::diagnose(&rec, &Options::default()).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        let confirmation = format!("{:?}", r.report.confirmation);
        (r.report.verdict.answer(), confirmation)
    }

    /// A force leak at its stated limit (1e-5) on a toleranced development device (`lod 3
    /// 303 DIR 7`, its record `force_leak-3-1`): the re-simulation with the leak fitted at
    /// −1.04e-5 brings the record to 1.07 × its noise, but three rows (drive DC, drive 1st
    /// quadrature, sense 1st quadrature) were left 0.41, 0.59 and 1.58 above their noise
    /// levels, more than half their gaps, and the verdict was `unknown`. Each is below 3 ×
    /// the row's own scatter at the noise (0.47, 1.00, 2.40: `NOISE_ROW_SCATTER` × ν²), so
    /// with `ROW_SCATTER_SIGMAS` it is named.
    #[test]
    fn a_force_leak_at_its_limit_is_named() {
        let sc = Scenario::load("characterise").unwrap();
        let t = Target::Library(Effect::ForceLeak);
        let ti = Target::all().iter().position(|&x| x == t).unwrap();
        let size = grid(size_range(Effect::ForceLeak), 7)[3];
        let d = draw_at(t, size, "fl".into(), &mut job_rng(303, ti, 3, 1));
        let (answer, confirmation) = verdict_of(&sc, &d, "fl");
        assert_eq!(
            answer,
            crate::diagnose::Answer::Effect(Effect::ForceLeak),
            "{confirmation}"
        );
    }

    /// The grid spans the drawn range, ends included, log-spaced.
    #[test]
    fn grid_spans_the_range_log_spaced() {
        let g = grid(super::super::r(1e-9, 1e-5, 1e-7, true), 5);
        assert_eq!(g.len(), 5);
        assert!((g[0] - 1e-9).abs() < 1e-21 && (g[4] - 1e-5).abs() < 1e-17);
        assert!((g[2] - 1e-7).abs() < 1e-19);
    }
}
