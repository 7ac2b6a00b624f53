//! The benchmark draw: N records with their truth, written as `DIR/NNNN.csv`, then
//! `DIR/labels.json` (the blind benchmark's `Labels` format plus this generator's own
//! fields).
//!
//! Categories as the blind benchmark (cumulative shares [`SHARES`]): 20 % clean, 45 % one
//! library effect, 10 % two library effects, 25 % one effect out of the library. Sizes are
//! log-uniform over the blind benchmark's ranges, signs random where the effect has both
//! (the thermal drift negative, as in silicon), the vibration's beat ±[0.5, 5] Hz and its
//! phase uniform, the electrostatic softening the pump-driven one (`@1`).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Context;
use rand::{Rng, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::device::DeviceDraw;
use crate::effects::{Effect, EffectSizes, EffectSpec, LIBRARY, Outside, OutsideSpec, SizeRange};
use crate::format::{self, Header};
use crate::protocol::Protocol;
use crate::sim::{self, FrontEnd};

/// Cumulative shares: clean, one library effect, two, (the rest) out of library.
pub const SHARES: [f64; 3] = [0.20, 0.65, 0.75];

/// What a record holds (labels' `category`).
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

/// One record's truth (labels' `records` entries).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Draw {
    /// Record id: the file's stem (`0007` for `0007.csv`).
    pub id: String,
    /// What it holds.
    pub category: Category,
    /// Library effects (and the simulator's two out-of-library ones) with their sizes.
    pub effects: Vec<EffectSpec>,
    /// Noise seed.
    pub seed: u64,
    /// Die temperature rise over the record, K.
    pub temp_rise_k: f64,
    /// The device: tolerances, rate, accelerations, noise.
    pub device: DeviceDraw,
    /// The blind benchmark's out-of-library type, if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outside: Option<OutsideSpec>,
    /// The record's file name in the output directory.
    pub file: String,
    /// The angular vibration's phase at t = 0, rad (0 without it).
    pub vib_phase_rad: f64,
    /// The excitation protocol.
    pub protocol: Protocol,
}

/// labels.json.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Labels {
    /// The seed of the draw.
    pub seed: u64,
    /// The records' truth, in id order.
    pub records: Vec<Draw>,
    /// `paragyro-refsim-labels 1`.
    pub format: String,
    /// `paragyro-refsim VERSION`.
    pub generator: String,
    /// The lock-in of every record's header (order, cut-off Hz).
    pub lockin: (usize, f64),
}

/// A log-uniform magnitude in `r`, with a random sign when `r.signed`.
fn draw_size(rng: &mut impl Rng, r: SizeRange) -> f64 {
    let size = (r.low.ln() + rng.random::<f64>() * (r.high.ln() - r.low.ln())).exp();
    if r.signed && rng.random::<bool>() {
        -size
    } else {
        size
    }
}

fn draw_effect(rng: &mut impl Rng, e: Effect) -> EffectSpec {
    let mut size = draw_size(rng, e.size_range());
    if e == Effect::ThermalDrift {
        size = -size.abs();
    }
    let param = match e {
        Effect::AngularVibration => {
            let b = ((0.5 + 4.5 * rng.random::<f64>()) * 100.0).round() / 100.0;
            Some(if rng.random::<bool>() { b } else { -b })
        }
        Effect::ElectrostaticSoftening => Some(1.0),
        _ => None,
    };
    EffectSpec {
        effect: e,
        size,
        param,
    }
}

/// The out-of-library types drawn: the blind benchmark's four and the simulator's two.
const OUTSIDE_TYPES: usize = 6;

/// The share of records with a rate-table reversal, by default.
pub const REVERSAL_SHARE: f64 = 0.4;

/// Draws the labels of `n` records of `duration_s` from `seed`, a share `reversal_share`
/// of them with a rate-table reversal.
pub fn draw(n: usize, seed: u64, duration_s: f64, reversal_share: f64) -> Vec<Draw> {
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x0e5f_51a0_7e11_ab1e);
    (0..n)
        .map(|i| {
            let u: f64 = rng.random();
            let pick = |rng: &mut Xoshiro256PlusPlus| LIBRARY[rng.random_range(0..LIBRARY.len())];
            let mut outside = None;
            let (category, effects) = if u < SHARES[0] {
                (Category::None, Vec::new())
            } else if u < SHARES[1] {
                let e = pick(&mut rng);
                (Category::Single, vec![draw_effect(&mut rng, e)])
            } else if u < SHARES[2] {
                let a = pick(&mut rng);
                let mut b = pick(&mut rng);
                while b == a {
                    b = pick(&mut rng);
                }
                let pair = vec![draw_effect(&mut rng, a), draw_effect(&mut rng, b)];
                (Category::Double, pair)
            } else {
                let t = rng.random_range(0..OUTSIDE_TYPES);
                if t < Outside::ALL.len() {
                    let kind = Outside::ALL[t];
                    let size = draw_size(&mut rng, kind.size_range());
                    outside = Some(OutsideSpec { kind, size });
                    (Category::Outside, Vec::new())
                } else {
                    let e = [Effect::QuadraticStiffness, Effect::ReadoutGain][t - 4];
                    (Category::Outside, vec![draw_effect(&mut rng, e)])
                }
            };
            let seed = rng.random::<u32>() as u64;
            let temp_rise_k = ((2.0 + 6.0 * rng.random::<f64>()) * 100.0).round() / 100.0;
            let device = DeviceDraw::draw(&mut rng);
            let vib_phase_rad = if effects.iter().any(|e| e.effect == Effect::AngularVibration) {
                std::f64::consts::TAU * rng.random::<f64>()
            } else {
                0.0
            };
            let protocol = Protocol::draw(
                &mut rng,
                duration_s,
                device.pump_centre_hz(),
                device.rate_dps,
                device.accel_mps2,
                temp_rise_k,
                reversal_share,
            );
            Draw {
                id: format!("{i:04}"),
                category,
                effects,
                seed,
                temp_rise_k,
                device,
                outside,
                file: format!("{i:04}.csv"),
                vib_phase_rad,
                protocol,
            }
        })
        .collect()
}

impl Draw {
    /// The effect sizes of this record.
    pub fn sizes(&self) -> EffectSizes {
        let mut e = EffectSizes::of(&self.effects, self.outside);
        e.vib_phase = self.vib_phase_rad;
        e
    }

    /// Simulates this record through a front end of the given low-pass, at the
    /// integrator's relative tolerance `rtol`.
    pub fn simulate(
        &self,
        lpf_order: usize,
        lpf_hz: f64,
        rtol: f64,
    ) -> anyhow::Result<sim::Simulated> {
        let fe = FrontEnd {
            lpf_order,
            lpf_hz,
            rtol,
            noise_pm_rthz: self.device.noise_pm_rthz,
            seed: self.seed,
            ..FrontEnd::default()
        };
        sim::simulate(&self.device.si(), &self.sizes(), &self.protocol, &fe)
            .map_err(anyhow::Error::msg)
            .with_context(|| format!("simulating record {}", self.id))
    }

    /// The record's header.
    pub fn header(&self, lpf_order: usize, lpf_hz: f64) -> Header {
        Header {
            lpf_order,
            lpf_hz,
            fs_hz: self.protocol.fs_hz,
            pump_amp_ref_v: self.protocol.pump_amp_ref_v,
            extra: vec![
                (
                    "generator".into(),
                    format!("paragyro-refsim {}", env!("CARGO_PKG_VERSION")),
                ),
                ("device".into(), "reference".into()),
            ],
        }
    }
}

/// Options of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct GenOptions {
    /// Number of records.
    pub n: usize,
    /// Seed of the draw.
    pub seed: u64,
    /// Duration of each record, s.
    pub duration_s: f64,
    /// Lock-in order and cut-off of the records' front end and header.
    pub lpf: (usize, f64),
    /// V_A0 of the headers, V.
    pub pump_amp_ref_v: f64,
    /// The integrator's relative tolerance.
    pub rtol: f64,
    /// The share of records with a rate-table reversal.
    pub reversal_share: f64,
    /// Writes only these of the `n` drawn records (ids, `0039`), e.g. to reproduce a record
    /// of a scored run; labels.json then holds only them. Empty: all.
    pub only: Vec<String>,
    /// Writes only the drawn records of this category (a development set of one kind);
    /// `None`: all.
    pub category: Option<Category>,
}

/// What a run did.
#[derive(Clone, Debug, PartialEq)]
pub struct GenReport {
    /// The records written.
    pub records: Vec<PathBuf>,
    /// labels.json.
    pub labels: PathBuf,
    /// Wall time, s.
    pub seconds: f64,
    /// Sum over records of each record's own simulation time, s.
    pub cpu_seconds: f64,
}

/// Writes the records into `dir`, then labels.json. `progress` gets one line per record.
pub fn generate(
    opts: &GenOptions,
    dir: &Path,
    progress: &(dyn Fn(&str) + Sync),
) -> anyhow::Result<GenReport> {
    anyhow::ensure!(opts.n > 0, "--n must be at least 1");
    anyhow::ensure!(
        opts.rtol.is_finite() && (1e-13..=1e-4).contains(&opts.rtol),
        "--rtol {} must be in [1e-13, 1e-4]",
        opts.rtol
    );
    anyhow::ensure!(
        opts.duration_s.is_finite() && opts.duration_s >= 0.01,
        "--duration-s {} must be at least 0.01 s",
        opts.duration_s
    );
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let labels_path = dir.join("labels.json");
    // stale labels must never sit beside new records
    if labels_path.exists() {
        std::fs::remove_file(&labels_path)
            .with_context(|| format!("cannot remove the old {}", labels_path.display()))?;
    }
    anyhow::ensure!(
        (0.0..=1.0).contains(&opts.reversal_share),
        "--reversal-share {} must be in [0, 1]",
        opts.reversal_share
    );
    let mut draws = draw(opts.n, opts.seed, opts.duration_s, opts.reversal_share);
    for id in &opts.only {
        anyhow::ensure!(
            draws.iter().any(|d| &d.id == id),
            "--only {id}: no such record among the {} drawn (ids 0000 to {:04})",
            opts.n,
            opts.n - 1
        );
    }
    // the selection happens after the whole draw, so a record is the same whatever is kept
    draws.retain(|d| {
        (opts.only.is_empty() || opts.only.contains(&d.id))
            && opts.category.is_none_or(|c| d.category == c)
    });
    anyhow::ensure!(
        !draws.is_empty(),
        "none of the {} drawn records is of the category asked (--category)",
        opts.n
    );
    for d in &mut draws {
        d.protocol.pump_amp_ref_v = opts.pump_amp_ref_v;
    }
    let n = draws.len();
    let t0 = Instant::now();
    let done = AtomicUsize::new(0);
    let (order, hz) = opts.lpf;
    let results: Vec<anyhow::Result<(PathBuf, f64)>> = draws
        .par_iter()
        .map(|d| {
            let t = Instant::now();
            let s = d.simulate(order, hz, opts.rtol)?;
            let path = dir.join(&d.file);
            format::write(&path, &d.header(order, hz), &s.rows)?;
            let secs = t.elapsed().as_secs_f64();
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            // no truth on the progress line: the labels stay sealed until labels.json
            progress(&format!(
                "[{k}/{n}] {} ({:.1} s, {} steps)",
                path.display(),
                secs,
                s.stats.accepted
            ));
            Ok((path, secs))
        })
        .collect();
    let mut records = Vec::with_capacity(n);
    let mut cpu_seconds = 0.0;
    for r in results {
        let (p, s) = r?;
        records.push(p);
        cpu_seconds += s;
    }
    let labels = Labels {
        seed: opts.seed,
        records: draws,
        format: "paragyro-refsim-labels 1".into(),
        generator: format!("paragyro-refsim {}", env!("CARGO_PKG_VERSION")),
        lockin: opts.lpf,
    };
    let text = serde_json::to_string_pretty(&labels)?;
    let tmp = dir.join("labels.json.part");
    std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, &labels_path)
        .with_context(|| format!("cannot write {}", labels_path.display()))?;
    Ok(GenReport {
        records,
        labels: labels_path,
        seconds: t0.elapsed().as_secs_f64(),
        cpu_seconds,
    })
}
