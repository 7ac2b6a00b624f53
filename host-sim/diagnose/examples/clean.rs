//! Clean devices with tolerances, diagnosed (development of the `none` gate and the
//! parameter intervals): `cargo run --release -p paragyro-diagnose --example clean -- FIRST
//! COUNT` draws devices `tol=FIRST..FIRST+COUNT` as the blind benchmark does (no effect,
//! a rate table, the die warming 4 K or
//! `TEMP_RISE_K`; `NOISE_PM` sets every device's noise density, `ACCEL0` zeroes the
//! accelerations) and prints, per device, the verdict, the held-out
//! residual over the record's noise, the estimated against the true noise energy ratio,
//! each device parameter's (calibrated − true)/σ and the held-out energy per row over ν²;
//! then the 1σ coverage (per parameter, per device, and how much a run of 14 clean devices
//! would scatter with these z's correlations and exact σ: [`print_clustering`]), the mean
//! energy per row over ν² (`NOISE_ROW_PROFILE`) and its
//! standard deviation across the devices (`NOISE_ROW_SCATTER`), and how the held-out
//! residual over the noise and the sense 1st-harmonic rows follow each property of the
//! draw (correlation across the devices).

use paragyro_diagnose::blind::device::DeviceDraw;
use paragyro_diagnose::diagnose::{Options, diagnose};
use paragyro_simulator::record::{RecordOptions, simulate_record_with};
use paragyro_simulator::scenario::Scenario;
use rand::SeedableRng;
use rayon::prelude::*;

/// A device's printed line, its parameters' z, its held-out energy per row over ν² (as it
/// is, and less the record's own noise per row), and its draw's properties ([`FEATURES`])
/// with its held-out residual over the noise.
type DeviceLine = (String, (Vec<f64>, Vec<f64>, Vec<f64>), (Vec<f64>, f64));

/// The properties of a draw the last lines correlate with.
const FEATURES: [&str; 15] = [
    "rate", "|rate|", "accel_x", "accel_y", "noise", "mu_x", "mu_y", "mu_xy", "wx2", "wy2", "wxy2",
    "alpha_x", "alpha_y", "beta1", "beta3",
];

fn main() -> anyhow::Result<()> {
    let args: Vec<u64> = std::env::args()
        .skip(1)
        .map(|a| a.parse())
        .collect::<Result<_, _>>()?;
    let [first, count] = args[..] else {
        anyhow::bail!("usage: clean FIRST COUNT");
    };
    let sc = Scenario::load("characterise")?;
    // the die's warming over the record, K (TEMP_RISE_K; the blind benchmark draws 2–8)
    // the noise density, pm/√Hz (NOISE_PM; default: the device's draw)
    let noise_pm: Option<f64> = std::env::var("NOISE_PM")
        .ok()
        .map(|v| v.parse())
        .transpose()?;
    let temp_rise: f64 = std::env::var("TEMP_RISE_K").map_or(Ok(4.0), |v| v.parse())?;
    let names = paragyro_core::physics::PHYSICAL_NAMES;
    let rows: Vec<anyhow::Result<DeviceLine>> = (first..first + count)
        .into_par_iter()
        .map(|s| {
            let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(s);
            let mut dev = DeviceDraw::draw(&mut rng);
            if let Some(pm) = noise_pm {
                dev.noise_pm_rthz = pm;
            }
            if std::env::var("ACCEL0").is_ok() {
                dev.accel_mps2 = [0.0; 2];
            }
            let opts = RecordOptions {
                seed: Some(1000 + s),
                rate_table: true,
                temp: Some((25.0, temp_rise)),
                ..RecordOptions::default()
            };
            let (rec, _) = simulate_record_with(&dev.apply(&sc), &opts, &mut |_| {})?;
            let r = diagnose(&rec, &Options::default())?.report;
            let truth = dev.physical(&sc).as_array();
            let z: Vec<f64> = (0..10)
                .map(|i| {
                    let p = r
                        .parameter_face
                        .parameters
                        .iter()
                        .find(|p| p.name == names[i])
                        .expect("every device parameter is calibrated");
                    (p.device - truth[i]) / p.sigma
                })
                .collect();
            let wy2 = r
                .parameter_face
                .parameters
                .iter()
                .find(|p| p.name == "wy2")
                .expect("wy2 is calibrated");
            let line = format!(
                "tol={s:<4} {:<8} res/noise {:.3}  nu2 {:.3} (true {:.3})  wy2 {:+.4} ± {:.4} ppm  z {}",
                r.verdict.to_string(),
                r.residual_over_noise,
                r.parameter_face.noise_energy_ratio,
                dev.noise_pm_rthz.powi(2),
                1e6 * (wy2.device - truth[4]) / truth[4],
                1e6 * wy2.sigma / truth[4],
                z.iter()
                    .map(|v| format!("{v:+6.2}"))
                    .collect::<Vec<_>>()
                    .join(" ")
            );
            // each row's held-out energy after the baseline fit, over the record's ν²
            let per_row: Vec<f64> = r
                .held_out_by_row
                .iter()
                .map(|e| e.baseline / r.parameter_face.noise_energy_ratio)
                .collect();
            let f2 = |v: &[f64]| v.iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>().join(" ");
            let line = format!(
                "{line}\n         rows / nu2 {}\n         the record's noise per row {}",
                f2(&per_row),
                f2(&r.noise_per_row)
            );
            let mut feat = vec![
                dev.rate_dps,
                dev.rate_dps.abs(),
                dev.accel_mps2[0],
                dev.accel_mps2[1],
                dev.noise_pm_rthz,
            ];
            feat.extend(dev.deviations);
            // each row's held-out energy over ν² less the record's own noise level for it
            let over_own: Vec<f64> = per_row
                .iter()
                .zip(&r.noise_per_row)
                .map(|(e, n)| e - n)
                .collect();
            Ok((line, (z, per_row, over_own), (feat, r.residual_over_noise)))
        })
        .collect();
    let mut all = Vec::new();
    let mut rows_all: Vec<Vec<f64>> = Vec::new();
    let mut own_all: Vec<Vec<f64>> = Vec::new();
    let mut draws = Vec::new();
    for r in rows {
        let (line, (z, per_row, over_own), draw) = r?;
        println!("{line}");
        all.push(z);
        rows_all.push(per_row);
        own_all.push(over_own);
        draws.push(draw);
    }
    // the mean and sample standard deviation across the devices, per row: how far a row's
    // held-out energy at the noise scatters from one record to the next
    // (`NOISE_ROW_SCATTER`), and about each record's own level (`NOISE_ROW_SCATTER_OWN`)
    let (mean, sd) = mean_sd(&rows_all);
    let (mean_own, sd_own) = mean_sd(&own_all);
    let fmt = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{x:.3}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!(
        "held-out energy per row / nu2, mean over the devices: {}",
        fmt(&mean)
    );
    println!(
        "held-out energy per row / nu2, standard deviation across the devices: {}",
        fmt(&sd)
    );
    println!(
        "held-out energy per row / nu2 less the record's own noise per row, mean: {}",
        fmt(&mean_own)
    );
    println!(
        "held-out energy per row / nu2 less the record's own noise per row, standard deviation: {}",
        fmt(&sd_own)
    );
    println!("z columns: {:?}", &names[..10]);
    for i in 0..10 {
        let c = all.iter().filter(|z| z[i].abs() <= 1.0).count();
        let rms = (all.iter().map(|z| z[i] * z[i]).sum::<f64>() / all.len() as f64).sqrt();
        let mean = all.iter().map(|z| z[i]).sum::<f64>() / all.len() as f64;
        println!(
            "{:<8} covered {c}/{}  mean z {mean:+.2}  rms z {rms:.2}",
            names[i],
            all.len()
        );
    }
    let c: usize = all
        .iter()
        .map(|z| z.iter().filter(|v| v.abs() <= 1.0).count())
        .sum();
    println!("1σ coverage {c}/{}", 10 * all.len());
    print_clustering(&all);
    print_correlations(&draws, &rows_all);
    Ok(())
}

/// Why the coverage clusters by device and scatters from run to run: the z of one
/// device's ten parameters come from one fit and are correlated. Prints the per-device
/// covered counts, the correlation of the z across the devices and its eigenvalues, and
/// the coverage of 20 000 simulated runs of 14 clean devices (the blind benchmark's
/// 13–15) whose z are Gaussian with that correlation and unit variance (σ exact): the
/// scatter a run's coverage has from the correlations alone.
fn print_clustering(all: &[Vec<f64>]) {
    use nalgebra::{DMatrix, SymmetricEigen};
    use rand::Rng;
    let n = all.len();
    let mut hist = [0usize; 11];
    for z in all {
        hist[z.iter().filter(|v| v.abs() <= 1.0).count()] += 1;
    }
    println!("devices with 0..=10 of 10 covered: {hist:?}");
    let col = |i: usize| -> Vec<f64> { all.iter().map(|z| z[i]).collect() };
    let c = DMatrix::from_fn(
        10,
        10,
        |i, k| if i == k { 1.0 } else { corr(&col(i), &col(k)) },
    );
    println!("correlation of the z across the devices:");
    for i in 0..10 {
        let r: Vec<String> = (0..10).map(|k| format!("{:+.2}", c[(i, k)])).collect();
        println!("  {}", r.join(" "));
    }
    let mut ev: Vec<f64> = SymmetricEigen::new(c.clone())
        .eigenvalues
        .iter()
        .copied()
        .collect();
    ev.sort_by(|a, b| b.total_cmp(a));
    let ev: Vec<String> = ev.iter().map(|v| format!("{v:.2}")).collect();
    println!("its eigenvalues: {}", ev.join(" "));
    // Gaussian z with correlation c (its Cholesky factor; a tiny ridge for the near-singular
    // directions), 14 devices per run
    let Some(l) = (c + DMatrix::identity(10, 10) * 1e-9).cholesky() else {
        return;
    };
    let l = l.l();
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(0x636c_7573);
    let mut gauss = move || {
        let (u1, u2): (f64, f64) = (rng.random(), rng.random());
        (-2.0 * (1.0 - u1).ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let runs = 20_000;
    let mut cov: Vec<f64> = (0..runs)
        .map(|_| {
            let mut k = 0usize;
            for _ in 0..14 {
                let g = nalgebra::DVector::from_fn(10, |_, _| gauss());
                k += (&l * g).iter().filter(|v| v.abs() <= 1.0).count();
            }
            k as f64 / 140.0
        })
        .collect();
    cov.sort_by(f64::total_cmp);
    let m = cov.iter().sum::<f64>() / runs as f64;
    let sd = (cov.iter().map(|v| (v - m).powi(2)).sum::<f64>() / runs as f64).sqrt();
    println!(
        "runs of 14 devices with these correlations and exact σ: coverage {:.1} % ± {:.1} % (5–95 %: {:.1}–{:.1} %; {n} devices measured)",
        100.0 * m,
        100.0 * sd,
        100.0 * cov[runs / 20],
        100.0 * cov[runs * 19 / 20]
    );
}

/// Per column of equally long rows: the mean and the sample standard deviation.
fn mean_sd(rows: &[Vec<f64>]) -> (Vec<f64>, Vec<f64>) {
    let nrow = rows.first().map_or(0, Vec::len);
    let n = rows.len() as f64;
    let mean: Vec<f64> = (0..nrow)
        .map(|i| rows.iter().map(|v| v[i]).sum::<f64>() / n)
        .collect();
    let sd = (0..nrow)
        .map(|i| {
            let ss = rows.iter().map(|v| (v[i] - mean[i]).powi(2)).sum::<f64>();
            (ss / (n - 1.0).max(1.0)).sqrt()
        })
        .collect();
    (mean, sd)
}

/// Pearson correlation of two equally long series (0 when either is constant).
fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let cov: f64 = a.iter().zip(b).map(|(x, y)| (x - ma) * (y - mb)).sum();
    let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
    let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
    if va > 0.0 && vb > 0.0 {
        cov / (va * vb).sqrt()
    } else {
        0.0
    }
}

/// How the held-out residual over the noise and the sense 1st-harmonic rows' energy over
/// ν² (their mean, `ROW_LABELS` 6 and 7: the rows that scatter most at the noise) follow
/// each property of the draw, across the devices.
fn print_correlations(draws: &[(Vec<f64>, f64)], rows_all: &[Vec<f64>]) {
    let res: Vec<f64> = draws.iter().map(|d| d.1).collect();
    let sense1: Vec<f64> = rows_all.iter().map(|r| 0.5 * (r[6] + r[7])).collect();
    println!("correlation across the devices with: residual/noise, sense 1st-harmonic rows / nu2");
    for (i, name) in FEATURES.iter().enumerate() {
        let f: Vec<f64> = draws.iter().map(|d| d.0[i]).collect();
        println!("{name:<8} {:+.2} {:+.2}", corr(&f, &res), corr(&f, &sense1));
    }
}
