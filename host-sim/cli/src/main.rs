//! `paragyro-sim`: the command line of the simulator.
//!
//! ```text
//! paragyro-sim list                                   built-in scenarios
//! paragyro-sim check <scenario|file.toml>             load and validate, print the resolved settings
//! paragyro-sim run <scenario|file.toml> --out DIR     run, write summary.json, trace.csv, plots
//!              [--seed N] [--precision f32|f64] [--quiet]
//! paragyro-sim demo [--out DIR] [--precision ...]     the built-in drift-retune, with a summary
//! paragyro-sim results                                every built-in, f32 and f64: the README table
//! paragyro-sim calibrate <scenario|file.toml>         row noise (weights) with the true θ
//!              [--from S] [--steps-per-period N]
//! paragyro-sim averaged [--out DIR]                   seed 000's averaged model, band, sweeps
//! paragyro-sim paper-001 [--out DIR]                  seed 001's stationary regimes, Figs 3–4
//! paragyro-sim paper-claims                           the "20 %" claim, reading by reading
//! paragyro-sim paper-raw [--out DIR]                  the paper's own estimator on the raw signals
//! paragyro-sim record <scenario|file.toml>            a simulated record (docs/record-format.md)
//!              --out FILE.csv [--seed N]               and its truth, FILE.truth.json
//! paragyro-sim replay FILE.csv --out DIR              the core open-loop on a record:
//!              [--precision f32|f64]                   estimates.csv, summary.json
//! ```
//!
//! Exit codes: 0 success; 1 the run or the outputs failed; 2 the scenario could not be loaded
//! (or the command line is wrong). Errors are printed as `error: <message>` with their causes;
//! no panic traces.

use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use paragyro_simulator::record;
use paragyro_simulator::report;
use paragyro_simulator::runner::{self, Precision, RunOptions};
use paragyro_simulator::scenario::Scenario;
use paragyro_simulator::trace::RunResult;

/// Exit code of a failed run or output.
const EXIT_RUN: u8 = 1;
/// Exit code of a scenario that cannot be loaded.
const EXIT_LOAD: u8 = 2;
/// Runs shorter than this (simulated seconds, main + twin) get no progress bar.
const PROGRESS_MIN_SIM_S: f64 = 2.0;

/// Simulated parametrically excited MEMS gyroscope driving the paragyro core.
#[derive(Parser, Debug)]
#[command(name = "paragyro-sim", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// List the built-in scenarios.
    List,
    /// Load and validate a scenario (built-in name or TOML file) without running it.
    Check {
        /// Built-in scenario name or path to a scenario TOML file.
        scenario: String,
    },
    /// Run a scenario; write summary.json, trace.csv and the plots.
    Run {
        /// Built-in scenario name or path to a scenario TOML file.
        scenario: String,
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Override the scenario's noise seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Precision of the core.
        #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
        precision: PrecisionArg,
        /// No progress bar.
        #[arg(long, short)]
        quiet: bool,
    },
    /// Run every built-in scenario with the f32 and the f64 core; print a Markdown table.
    Results,
    /// Measure the residual std of each regression row with the true θ (the row weights
    /// `row_sigma_*` of the core's configuration) on a scenario.
    Calibrate {
        /// Built-in scenario name or path to a scenario TOML file.
        scenario: String,
        /// Start of the measurement window, s (after start-up and the dither onset).
        #[arg(long, default_value_t = 2.0)]
        from: f64,
        /// RK4 steps per carrier period (high, so the integrator's error is not counted as noise).
        #[arg(long, default_value_t = 512)]
        steps_per_period: usize,
    },
    /// Seed 000, averaged slow flow: steady states, stability, rest-state band, sweeps with hysteresis.
    Averaged {
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
    },
    /// Seed 001: stationary regimes and stability, Figs 3–4, RK4 checks of eq. (19), the paper's claims.
    #[command(name = "paper-001")]
    Paper001 {
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
    },
    /// The paper's own estimator (eqs. 10–19) on the raw signals: the ±50 % test with three
    /// λ readings and a side by side with the 500 Hz estimator; plots and paper_raw_summary.json.
    PaperRaw {
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR", default_value = "out/paper-raw")]
        out: PathBuf,
    },
    /// Seed 000's "sense amplitude drops to 20 %" claim, reading by reading (full-rate plant).
    #[command(name = "paper-claims")]
    PaperClaims,
    /// Simulate a scenario as a record (CSV at 500 Hz, docs/record-format.md); its truth
    /// goes to FILE.truth.json beside it.
    Record {
        /// Built-in scenario name or path to a scenario TOML file.
        scenario: String,
        /// The record to write (the truth goes to FILE.truth.json).
        #[arg(long, value_name = "FILE.csv")]
        out: PathBuf,
        /// Override the scenario's noise seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Add an effect to the simulated device: NAME=SIZE (angular_vibration=SIZE@BEAT_HZ);
        /// repeatable. Names and units: `paragyro-sim effects`.
        #[arg(long = "effect", value_name = "NAME=SIZE")]
        effects: Vec<paragyro_simulator::effects::EffectSpec>,
        /// Die temperature START_C:RISE_K (linear over the run), written as temp_c.
        #[arg(long, value_name = "START_C:RISE_K", value_parser = parse_temp)]
        temp: Option<(f64, f64)>,
        /// A rate table is present: write the true rate as rate_ref_dps.
        #[arg(long)]
        rate_table: bool,
    },
    /// List the effects the simulator can add (names, units, what they add).
    Effects,
    /// Blind benchmark of the diagnosis: draw N records with withheld effects, seal the
    /// labels, diagnose each, score (score.md, score.json).
    Blind {
        /// Number of records.
        #[arg(long, default_value_t = 100)]
        n: usize,
        /// Seed of the draw (the development seeds were 1 and 2; score on others).
        #[arg(long)]
        seed: u64,
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
    },
    /// Diagnose the gap between a record and the simulator: where it lies, which effect
    /// causes it, how far it shrinks once that effect is added (report.md, report.json, PNGs).
    Diagnose {
        /// The record (CSV, docs/record-format.md). Its truth file is never read.
        record: PathBuf,
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// The simulator configuration to compare with: a built-in scenario name or a
        /// scenario TOML (its plant at t = 0); default Table 2.
        #[arg(long, value_name = "SCENARIO")]
        model: Option<String>,
        /// Skip the re-simulation (no output error, faster).
        #[arg(long)]
        no_resim: bool,
    },
    /// Run the core open-loop on a record; write estimates.csv and summary.json.
    Replay {
        /// The record (CSV, docs/record-format.md).
        record: PathBuf,
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR")]
        out: PathBuf,
        /// Precision of the core.
        #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
        precision: PrecisionArg,
    },
    /// Run the built-in `drift-retune` scenario, print its summary and write the plots.
    Demo {
        /// Output directory (created if needed).
        #[arg(long, value_name = "DIR", default_value = "out")]
        out: PathBuf,
        /// Precision of the core.
        #[arg(long, value_enum, default_value_t = PrecisionArg::F32)]
        precision: PrecisionArg,
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum PrecisionArg {
    /// `Estimator<f32>`, as on the chip.
    F32,
    /// `Estimator<f64>`, the host reference.
    F64,
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Self {
        match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
        }
    }
}

/// An error with its exit code.
struct Failure {
    code: u8,
    error: anyhow::Error,
}

fn fail(code: u8) -> impl FnOnce(anyhow::Error) -> Failure {
    move |error| Failure { code, error }
}

/// `START_C:RISE_K` → (start, rise).
fn parse_temp(s: &str) -> Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("'{s}': expected START_C:RISE_K, e.g. 25:5"))?;
    let num = |v: &str| {
        v.trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("'{v}' is not a finite number"))
    };
    Ok((num(a)?, num(b)?))
}

fn main() -> ExitCode {
    // A bug must not print a backtrace at the user: one line, then exit 101.
    std::panic::set_hook(Box::new(|info| {
        eprintln!("error: internal error (please report): {info}");
    }));
    let cli = Cli::parse();
    let mut stdout = std::io::stdout().lock();
    let mut stderr = std::io::stderr();
    let tty = std::io::stderr().is_terminal();
    ExitCode::from(execute(cli, &mut stdout, &mut stderr, tty))
}

/// Runs a parsed command; prints errors on `err`; returns the exit code.
fn execute(cli: Cli, out: &mut dyn Write, err: &mut dyn Write, progress_ok: bool) -> u8 {
    match dispatch(cli, out, progress_ok) {
        Ok(()) => 0,
        Err(f) if f.code == 0 => 0, // stdout closed: nothing left to say
        Err(f) => {
            let _ = writeln!(err, "error: {:#}", f.error);
            f.code
        }
    }
}

fn dispatch(cli: Cli, out: &mut dyn Write, progress_ok: bool) -> Result<(), Failure> {
    match cli.command {
        Command::List => {
            let list = Scenario::builtin_names();
            let width = list.iter().map(|(n, _)| n.len()).max().unwrap_or(0);
            let mut text = String::from(
                "Built-in scenarios (run with `paragyro-sim run <name> --out DIR`):\n",
            );
            for (name, desc) in list {
                text.push_str(&format!("  {name:<width$}  {desc}\n"));
            }
            text.push_str(
                "Or pass a scenario file (TOML, schema in host-sim/scenarios/README.md).\n",
            );
            say(out, &text)
        }
        Command::Check { scenario } => {
            let sc = load(&scenario)?;
            say(out, &describe(&sc))
        }
        Command::Run {
            scenario,
            out: dir,
            seed,
            precision,
            quiet,
        } => {
            if scenario == "paper-raw" {
                // not a scenario of the simulated gyro: the paper's own estimator
                let v = paragyro_papers::paper_raw::write_paper_raw_report(&dir)
                    .map_err(fail(EXIT_RUN))?;
                let mut text = format!(
                    "Wrote paper_raw_*.png and paper_raw_summary.json to {}\n\n",
                    dir.display()
                );
                text.push_str(v["table_md"].as_str().unwrap_or_default());
                return say(out, &text);
            }
            let sc = load(&scenario)?;
            let opts = RunOptions {
                precision: precision.into(),
                seed,
            };
            let result = run_with_progress(&sc, &opts, progress_ok && !quiet)?;
            let files = write(&dir, &result)?;
            let mut text = format!("Wrote {} files to {}:\n", files.len(), dir.display());
            for f in &files {
                text.push_str(&format!("  {}\n", f.display()));
            }
            text.push_str(&report::short_summary(&result));
            say(out, &text)
        }
        Command::Results => {
            let mut err = std::io::stderr();
            let md = paragyro_simulator::results::results_table(&mut |what| {
                let _ = writeln!(err, "running {what} ...");
            })
            .map_err(fail(EXIT_RUN))?;
            say(out, &md)
        }
        Command::Calibrate {
            scenario,
            from,
            steps_per_period,
        } => {
            let mut sc = load(&scenario)?;
            sc.sim.steps_per_period = steps_per_period;
            let (d, s) = runner::calibrate_rows(&sc, from).map_err(fail(EXIT_RUN))?;
            let f = |v: [f64; 5]| {
                v.iter()
                    .map(|x| format!("{x:.3e}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            say(
                out,
                &format!(
                    "Residual std per row with the true θ, per 1 pm/√Hz (rows: DC, h1 Re, h1 Im, h3 Re, h3 Im),\n\
                     scenario '{}', from {from} s, {steps_per_period} steps/period:\n\
                     row_sigma_drive = [{}]\nrow_sigma_sense = [{}]\n",
                    sc.name,
                    f(d),
                    f(s)
                ),
            )
        }
        Command::Averaged { out: dir } => {
            paragyro_papers::averaged::write_averaged_report(&dir).map_err(fail(EXIT_RUN))?;
            say(
                out,
                &format!(
                    "Wrote averaged_sweep.png and averaged.json to {}\n",
                    dir.display()
                ),
            )
        }
        Command::Paper001 { out: dir } => {
            paragyro_papers::paper001::write_paper001_report(&dir).map_err(fail(EXIT_RUN))?;
            say(
                out,
                &format!(
                    "Wrote paper001_fig3.png, paper001_fig4.png and paper001.json to {}\n",
                    dir.display()
                ),
            )
        }
        Command::PaperRaw { out: dir } => {
            let _ = writeln!(
                std::io::stderr(),
                "running the paper's raw-signal estimator (about 30 s) ..."
            );
            let v =
                paragyro_papers::paper_raw::write_paper_raw_report(&dir).map_err(fail(EXIT_RUN))?;
            let mut text = format!(
                "Wrote paper_raw_*.png and paper_raw_summary.json to {}\n\n",
                dir.display()
            );
            text.push_str(v["table_md"].as_str().unwrap_or_default());
            say(out, &text)
        }
        Command::PaperClaims => {
            let mut text = String::from(
                "| reading | assumption | sense before (µm) | after (µm) | ratio |\n|---|---|---|---|---|\n",
            );
            for r in paragyro_papers::claims::readings() {
                text.push_str(&format!(
                    "| {} | {} | {:.4} | {:.4} | {:.3} |\n",
                    r.name, r.description, r.sense_amp_before, r.sense_amp_after, r.ratio
                ));
            }
            say(out, &text)
        }
        Command::Blind { n, seed, out: dir } => {
            let mut err = std::io::stderr();
            let summary = paragyro_diagnose::blind::run(n, seed, &dir, &mut |m| {
                let _ = writeln!(err, "{m}");
            })
            .map_err(fail(EXIT_RUN))?;
            let p = |k: &str| {
                summary[k]
                    .as_f64()
                    .map_or("–".into(), |x| format!("{:.0} %", 100.0 * x))
            };
            say(
                out,
                &format!(
                    "Blind benchmark, N = {n}, seed {seed}:\n  top-1 (single, above limit) {}\n  unknown on out-of-library {}\n  false alarms on clean {}\n  median closure / oracle {}\nWrote {}/score.md and score.json\n",
                    p("top1_single_above_limit"),
                    p("unknown_on_outside"),
                    p("false_alarms_on_clean"),
                    p("median_closure_over_oracle"),
                    dir.display()
                ),
            )
        }
        Command::Effects => {
            let mut text = String::from("Effects the simulator can add (--effect NAME=SIZE):\n");
            for (name, what) in paragyro_simulator::effects::describe() {
                let lib = if paragyro_simulator::effects::LIBRARY.contains(&name) {
                    "library"
                } else {
                    "outside the library"
                };
                text.push_str(&format!("  {name:<24} {what} [{lib}]\n"));
            }
            say(out, &text)
        }
        Command::Record {
            scenario,
            out: file,
            seed,
            effects,
            temp,
            rate_table,
        } => {
            let sc = load(&scenario)?;
            let opts = record::RecordOptions {
                seed,
                effects,
                temp,
                rate_table,
            };
            let (files, rec) = record::write_simulated_record(&sc, &file, &opts, &mut |_| {})
                .with_context(|| format!("cannot record scenario '{}'", sc.name))
                .map_err(fail(EXIT_RUN))?;
            say(
                out,
                &format!(
                    "Wrote {} ({} samples, {} s at {} Hz) and its truth {}\n",
                    files.csv.display(),
                    rec.rows.len(),
                    rec.duration_s(),
                    rec.header.fs_hz,
                    files.truth.display()
                ),
            )
        }
        Command::Diagnose {
            record: file,
            out: dir,
            model,
            no_resim,
        } => {
            let rec = read_record_warn(&file)?;
            let mut err = std::io::stderr();
            let mut opts = paragyro_diagnose::diagnose::Options {
                resimulate: !no_resim,
                ..Default::default()
            };
            if let Some(m) = model {
                opts.model = paragyro_diagnose::diagnose::Model::from_scenario(&load(&m)?);
            }
            let _ = writeln!(
                err,
                "diagnosing {} ({} samples, {:.1} s){}",
                file.display(),
                rec.rows.len(),
                rec.duration_s(),
                if opts.resimulate {
                    ", with the re-simulation"
                } else {
                    ""
                }
            );
            let d = paragyro_diagnose::diagnose::diagnose(&rec, &opts)
                .with_context(|| format!("cannot diagnose {}", file.display()))
                .map_err(fail(EXIT_RUN))?;
            let name = file
                .file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned());
            let files =
                paragyro_diagnose::diagnose::write_report(&dir, &d, &name).map_err(fail(EXIT_RUN))?;
            let j = &d.json;
            let mut text = format!(
                "Verdict: {}{}\n",
                d.verdict,
                j["secondary"]["effect"]
                    .as_str()
                    .map(|e| format!(" (and {e})"))
                    .unwrap_or_default()
            );
            for c in d.ranking.iter().filter(|c| c.untestable.is_none()).take(3) {
                text.push_str(&format!(
                    "  {:<24} size {:.4e} ± {:.1e} {}  gap closure {:5.1} %{}\n",
                    c.effect,
                    c.size,
                    c.size_sigma,
                    paragyro_simulator::effects::unit(&c.effect),
                    100.0 * c.gap_closure,
                    if c.significant { "  significant" } else { "" }
                ));
            }
            text.push_str(&format!(
                "Held-out gap: {:.4e} → {:.4e} ({:.1} % closed); output error closure {}\n",
                j["gap_before"].as_f64().unwrap_or(f64::NAN),
                j["gap_after"].as_f64().unwrap_or(f64::NAN),
                100.0 * j["gap_closure"].as_f64().unwrap_or(f64::NAN),
                j["output_error"]["closure"]
                    .as_f64()
                    .map_or("not computed".into(), |v| format!("{:.1} %", 100.0 * v))
            ));
            text.push_str(&format!(
                "Took {:.2} s. Wrote {} files to {}\n",
                j["seconds"].as_f64().unwrap_or(f64::NAN),
                files.len(),
                dir.display()
            ));
            say(out, &text)
        }
        Command::Replay {
            record: file,
            out: dir,
            precision,
        } => {
            let rec = read_record_warn(&file)?;
            let source = file.display().to_string();
            let res = record::write_replay(&rec, &source, &dir, precision.into())
                .map_err(fail(EXIT_RUN))?;
            let mut text = res.text;
            text.push_str(&format!(
                "Wrote {} files to {}:\n",
                res.files.len(),
                dir.display()
            ));
            for f in &res.files {
                text.push_str(&format!("  {}\n", f.display()));
            }
            say(out, &text)
        }
        Command::Demo {
            out: dir,
            precision,
        } => {
            let sc = load("drift-retune")?;
            say(
                out,
                &format!(
                    "Demo: built-in scenario 'drift-retune' ({}).\n",
                    sc.description
                ),
            )?;
            let opts = RunOptions {
                precision: precision.into(),
                seed: None,
            };
            let result = run_with_progress(&sc, &opts, progress_ok)?;
            say(out, &report::print_summary(&result))?;
            let files = write(&dir, &result)?;
            let mut text = format!("\nPlots and data in {}:\n", dir.display());
            for f in &files {
                text.push_str(&format!("  {}\n", f.display()));
            }
            say(out, &text)
        }
    }
}

/// Reads a record; its warnings go to stderr, its error exits with EXIT_LOAD.
fn read_record_warn(file: &Path) -> Result<record::Record, Failure> {
    let rec = record::read_record(file).map_err(|e| Failure {
        code: EXIT_LOAD,
        error: anyhow::Error::new(e),
    })?;
    let mut err = std::io::stderr();
    for w in &rec.warnings {
        let _ = writeln!(err, "warning: {w}");
    }
    Ok(rec)
}

fn load(name_or_path: &str) -> Result<Scenario, Failure> {
    Scenario::load(name_or_path).map_err(|e| Failure {
        code: EXIT_LOAD,
        error: anyhow::Error::new(e),
    })
}

fn write(dir: &Path, result: &RunResult) -> Result<Vec<PathBuf>, Failure> {
    report::write_outputs(dir, result)
        .with_context(|| format!("cannot write the outputs to {}", dir.display()))
        .map_err(fail(EXIT_RUN))
}

/// Writes to stdout. A closed pipe (`paragyro-sim demo | head`) ends the command quietly;
/// other write errors are errors (exit 1); never a panic.
fn say(out: &mut dyn Write, text: &str) -> Result<(), Failure> {
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(Failure {
            code: 0,
            error: anyhow::Error::new(e),
        }),
        Err(e) => Err(Failure {
            code: EXIT_RUN,
            error: anyhow::Error::new(e).context("cannot write to stdout"),
        }),
    }
}

/// Runs with an indicatif bar on stderr (only when `show` and the run is long enough).
fn run_with_progress(sc: &Scenario, opts: &RunOptions, show: bool) -> Result<RunResult, Failure> {
    let sim_s = sc.duration_s * if sc.twin.is_some() { 2.0 } else { 1.0 };
    let bar = if show && sim_s >= PROGRESS_MIN_SIM_S {
        let bar = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr());
        let style = ProgressStyle::with_template(
            "{msg} [{bar:40.cyan/blue}] {percent:>3}%  {elapsed_precise} (eta {eta})",
        )
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_message(format!(
            "{} ({})",
            sc.name,
            match opts.precision {
                Precision::F32 => "f32",
                Precision::F64 => "f64",
            }
        ));
        bar
    } else {
        ProgressBar::hidden()
    };
    let mut progress = |f: f64| {
        if f.is_finite() {
            bar.set_position((f.clamp(0.0, 1.0) * 1000.0).round() as u64);
        }
    };
    let result = runner::run(sc, opts, &mut progress);
    bar.finish_and_clear();
    result
        .with_context(|| format!("the run of scenario '{}' failed", sc.name))
        .map_err(fail(EXIT_RUN))
}

/// The resolved settings of a scenario (for `check`).
fn describe(sc: &Scenario) -> String {
    let mut s = format!(
        "ok: '{}' from {}\n  {}\n  duration {} s, seed {}, f0 {:.3} Hz, {} steps/period, noise {} pm/√Hz, lock-in {} Hz order {}\n",
        sc.name,
        sc.source,
        sc.description,
        sc.duration_s,
        sc.seed,
        sc.sim.f0_hz,
        sc.sim.steps_per_period,
        sc.sim.noise_pm_rthz,
        sc.sim.lockin_lpf_hz,
        sc.sim.lockin_lpf_order
    );
    let e = &sc.estimator;
    s.push_str(&format!(
        "  pump centre {:.3} Hz, dither ±{} Hz at {} Hz from {} s, gate {} s, retune {}, forgetting {}\n",
        sc.pump_centre_hz(),
        e.dither_pump_hz,
        e.dither_freq_hz,
        e.dither_start_s,
        e.gate_startup_s,
        e.retune,
        e.forgetting
    ));
    s.push_str(&format!(
        "  plant: wy2 {}, rate {} °/s, accel {} / {} m/s²\n",
        sc.plant.wy2, sc.plant.rate_dps, sc.plant.accel_x_mps2, sc.plant.accel_y_mps2
    ));
    for ev in &sc.events {
        let what = match sc.pump_jump_centre_hz(ev) {
            Some(c) => format!("{} ({c:.3} Hz)", ev.kind),
            None => ev.kind.to_string(),
        };
        s.push_str(&format!("  event t = {} s: {what}\n", ev.t_s));
    }
    for m in &sc.measures {
        s.push_str(&format!(
            "  measure '{}': {:?} run, {}–{} s\n",
            m.name, m.run, m.from_s, m.to_s
        ));
    }
    if let Some(t) = sc.twin_scenario() {
        s.push_str(&format!(
            "  twin: retune {}, wy2 {}\n",
            t.estimator.retune, t.plant.wy2
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parses and executes a command line; returns (code, stdout, stderr).
    fn cli(args: &[&str]) -> (u8, String, String) {
        let mut argv = vec!["paragyro-sim"];
        argv.extend_from_slice(args);
        let parsed = Cli::try_parse_from(argv).unwrap();
        let (mut out, mut err) = (Vec::new(), Vec::new());
        let code = execute(parsed, &mut out, &mut err, false);
        (
            code,
            String::from_utf8(out).unwrap(),
            String::from_utf8(err).unwrap(),
        )
    }

    #[test]
    fn list_shows_every_builtin() {
        let (code, out, err) = cli(&["list"]);
        assert_eq!(code, 0, "{err}");
        for (name, _) in Scenario::builtin_names() {
            assert!(out.contains(name), "{out}");
        }
    }

    #[test]
    fn run_unknown_scenario_exits_2_listing_builtins() {
        let dir = std::env::temp_dir().join("paragyro-cli-test-unknown");
        let (code, out, err) = cli(&["run", "nonexistent", "--out", dir.to_str().unwrap()]);
        assert_eq!(code, EXIT_LOAD);
        assert!(out.is_empty());
        assert!(
            err.starts_with("error: unknown scenario 'nonexistent'"),
            "{err}"
        );
        for (name, _) in Scenario::builtin_names() {
            assert!(err.contains(name), "{err}");
        }
        assert!(!dir.exists(), "nothing written on a load error");
    }

    #[test]
    fn run_bad_file_exits_2_with_file_and_line() {
        let path =
            std::env::temp_dir().join(format!("paragyro-cli-bad-{}.toml", std::process::id()));
        std::fs::write(
            &path,
            "name = \"x\"\nduration_s = 1.0\n[plant]\nwy2 = \"high\"\n",
        )
        .unwrap();
        let p = path.to_str().unwrap();
        let (code, _, err) = cli(&["run", p, "--out", "/nonexistent-dir"]);
        assert_eq!(code, EXIT_LOAD);
        assert!(err.starts_with(&format!("error: {p}:4:")), "{err}");
        assert!(err.contains("plant.wy2"), "{err}");
        let (code, _, err) = cli(&["check", p]);
        assert_eq!(code, EXIT_LOAD, "{err}");
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn check_builtin() {
        let (code, out, err) = cli(&["check", "paper-switch"]);
        assert_eq!(code, 0, "{err}");
        assert!(out.starts_with("ok: 'paper-switch' from built-in"), "{out}");
        assert!(
            out.contains("pump jump to the sense resonance (26"),
            "{out}"
        );
    }

    #[test]
    fn record_then_replay() {
        let dir = std::env::temp_dir().join(format!("paragyro-cli-record-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let csv = dir.join("identify.csv");
        let (code, out, err) = cli(&[
            "record",
            "identify",
            "--out",
            csv.to_str().unwrap(),
            "--seed",
            "3",
        ]);
        assert_eq!(code, 0, "{err}");
        assert!(
            out.starts_with(&format!("Wrote {}", csv.display())),
            "{out}"
        );
        assert!(dir.join("identify.truth.json").exists());
        let rdir = dir.join("replay");
        let (code, out, err) = cli(&[
            "replay",
            csv.to_str().unwrap(),
            "--out",
            rdir.to_str().unwrap(),
            "--precision",
            "f64",
        ]);
        assert_eq!(code, 0, "{err}");
        assert!(out.starts_with("Replayed "), "{out}");
        assert!(rdir.join("estimates.csv").exists() && rdir.join("summary.json").exists());
        // a malformed record: exit 2, file:line:col in the message
        std::fs::write(&csv, "# format: paragyro-record 2\n").unwrap();
        let (code, _, err) = cli(&[
            "replay",
            csv.to_str().unwrap(),
            "--out",
            rdir.to_str().unwrap(),
        ]);
        assert_eq!(code, EXIT_LOAD);
        assert!(
            err.starts_with(&format!("error: {}:1:11: header 'format'", csv.display())),
            "{err}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn command_line_parsing() {
        let c = Cli::try_parse_from(["paragyro-sim", "run", "identify", "--out", "o"]).unwrap();
        match c.command {
            Command::Run {
                precision, seed, ..
            } => {
                assert_eq!(precision, PrecisionArg::F32);
                assert_eq!(seed, None);
            }
            other => panic!("{other:?}"),
        }
        let c = Cli::try_parse_from([
            "paragyro-sim",
            "run",
            "x.toml",
            "--out",
            "o",
            "--seed",
            "7",
            "--precision",
            "f64",
        ])
        .unwrap();
        assert!(matches!(
            c.command,
            Command::Run {
                seed: Some(7),
                precision: PrecisionArg::F64,
                ..
            }
        ));
        let c = Cli::try_parse_from(["paragyro-sim", "demo"]).unwrap();
        assert!(matches!(c.command, Command::Demo { ref out, .. } if out == Path::new("out")));
        // Missing --out, bad precision: clap errors (exit code 2 from clap itself).
        assert!(Cli::try_parse_from(["paragyro-sim", "run", "identify"]).is_err());
        let e = Cli::try_parse_from([
            "paragyro-sim",
            "run",
            "a",
            "--out",
            "o",
            "--precision",
            "f16",
        ])
        .unwrap_err();
        assert_eq!(e.exit_code(), 2);
    }
}
