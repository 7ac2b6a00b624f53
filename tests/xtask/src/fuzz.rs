//! `cargo xtask fuzz [--secs N] [TARGET ...]`: the libFuzzer run of `tests/fuzz`, bounded,
//! on the stable compiler.
//!
//! It does what `cargo fuzz run -s none` does without needing `cargo-fuzz` installed (that
//! install took ≈ 3 min on a fresh machine): the fuzz targets are built with the same
//! SanitizerCoverage flags (`-Cpasses=sancov-module`, inline 8-bit counters, the PC table,
//! compare tracing, `--cfg fuzzing`; no sanitizer, which would need nightly) for the host
//! triple named explicitly, so the flags reach the targets and not the build scripts, into
//! `target/libfuzzer/`. Each target then runs for `--secs` seconds (default 20) with a fixed
//! seed, two single-threaded targets side by side (one core each; `diagnosis`, whose
//! stages take both cores, alone), over
//!
//! * a scratch corpus `target/libfuzzer/corpus/<target>/` (what libFuzzer finds goes there,
//!   never into the repository),
//! * the committed seeds `tests/fuzz/seeds/<target>/` (and, for the scenario parser, the
//!   scenarios of `host-sim/scenarios/`),
//! * the crash regressions `tests/fuzz/regressions/<target>/`, each executed first.
//!
//! A crash, a timeout (an input running over 10 s) or an out-of-memory stops the run with
//! an error naming the saved input (`target/libfuzzer/artifacts/<target>/`); the fix comes
//! with that input copied into `tests/fuzz/regressions/<target>/`. The figures of each
//! target (runs, coverage, corpus) are printed and written to
//! `target/libfuzzer/summary.json`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::{Child, Command};

use crate::{cargo, say};

/// The targets, in the order they run (`tests/fuzz/Cargo.toml`'s `[[bin]]`s).
pub const TARGETS: [&str; 5] = [
    "ads131m08_frame",
    "record_reader",
    "scenario_parser",
    "estimator_step",
    "diagnosis",
];

/// What `cargo fuzz build -s none` passes (cargo-fuzz 0.12, `project.rs`), less the
/// sanitizer.
const SANCOV: &str = "-Cpasses=sancov-module \
    -Cllvm-args=-sanitizer-coverage-level=4 \
    -Cllvm-args=-sanitizer-coverage-inline-8bit-counters \
    -Cllvm-args=-sanitizer-coverage-pc-table \
    -Cllvm-args=-sanitizer-coverage-trace-compares \
    --cfg fuzzing";

/// Targets whose code runs on several threads (the diagnosis's rayon stages): fuzzed
/// alone; the others two at a time, one per core.
const THREADED: [&str; 1] = ["diagnosis"];

/// The targets (with their index, which gives the seed) in lanes run side by side: two
/// single-threaded ones together, a threaded one alone; in the given order otherwise.
fn lanes(targets: &[&'static str]) -> Vec<Vec<(usize, &'static str)>> {
    let mut lanes: Vec<Vec<(usize, &'static str)>> = Vec::new();
    let mut open: Option<usize> = None;
    for (i, &t) in targets.iter().enumerate() {
        if THREADED.contains(&t) {
            lanes.push(vec![(i, t)]);
        } else if let Some(k) = open.take() {
            lanes[k].push((i, t));
        } else {
            open = Some(lanes.len());
            lanes.push(vec![(i, t)]);
        }
    }
    lanes
}

/// Seconds per target when not given.
pub const DEFAULT_SECS: u32 = 20;

/// One target's run.
struct Figures {
    target: &'static str,
    runs: u64,
    cov: u64,
    corpus: u64,
    secs: u32,
}

/// Parses `[--secs N] [TARGET ...]` and runs.
pub fn fuzz(args: &[String]) -> Result<(), String> {
    let mut secs = DEFAULT_SECS;
    let mut targets: Vec<&'static str> = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        if a == "--secs" {
            let v = it.next().ok_or("--secs needs a number of seconds")?;
            secs = v
                .parse()
                .ok()
                .filter(|s| *s > 0)
                .ok_or_else(|| format!("--secs {v}: not a positive whole number of seconds"))?;
        } else if let Some(t) = TARGETS.iter().find(|t| **t == a.as_str()) {
            targets.push(t);
        } else {
            return Err(format!(
                "unknown fuzz target `{a}` (targets: {})",
                TARGETS.join(", ")
            ));
        }
    }
    if targets.is_empty() {
        targets = TARGETS.to_vec();
    }
    run_targets(&targets, secs)
}

/// Where the targets are built and run: the repository root and `target/libfuzzer`.
fn dirs() -> (PathBuf, PathBuf) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let root = root.canonicalize().unwrap_or(root);
    let out = root.join("target/libfuzzer");
    (root, out)
}

/// Builds the targets with coverage instrumentation and runs each for `secs` seconds.
pub fn run_targets(targets: &[&'static str], secs: u32) -> Result<(), String> {
    Build::start(false)?.finish()?;
    run_built(targets, secs)
}

/// The build of the fuzz targets into `target/libfuzzer/` (module docs), running.
pub struct Build {
    child: Child,
    /// The log it writes in the background (`None`: on the terminal).
    log: Option<PathBuf>,
}

impl Build {
    /// Starts the build: on the terminal, or in the `background` beside the tests' run,
    /// at the lowest CPU priority (`nice -n 19`, where there is one), its messages into
    /// `target/libfuzzer/build.log`.
    pub fn start(background: bool) -> Result<Build, String> {
        let (root, out) = dirs();
        let host = host_triple()?;
        let manifest = root.join("tests/fuzz/Cargo.toml");
        let (manifest_s, out_s) = (manifest.to_string_lossy(), out.to_string_lossy());
        let build = [
            "build",
            "--release",
            "--locked",
            "--manifest-path",
            &manifest_s,
            "--features",
            "libfuzzer",
            "--bins",
            "--target",
            &host,
            "--target-dir",
            &out_s,
        ];
        let mut cmd = if background && crate::found("nice") {
            let mut c = Command::new("nice");
            c.args(["-n", "19"]).arg(cargo());
            c
        } else {
            Command::new(cargo())
        };
        cmd.args(build)
            .env("RUSTFLAGS", SANCOV)
            .env_remove("CARGO_ENCODED_RUSTFLAGS");
        let log = if background {
            let log = out.join("build.log");
            std::fs::create_dir_all(&out)
                .map_err(|e| format!("cannot create {}: {e}", out.display()))?;
            let f = std::fs::File::create(&log)
                .map_err(|e| format!("cannot create {}: {e}", log.display()))?;
            let f2 = f
                .try_clone()
                .map_err(|e| format!("cannot write {}: {e}", log.display()))?;
            cmd.stdout(f).stderr(f2);
            Some(log)
        } else {
            None
        };
        say(&format!(
            "building the libFuzzer targets{}: RUSTFLAGS=\"{SANCOV}\" cargo {}",
            log.as_ref().map_or(String::new(), |l| format!(
                " (in the background, into {})",
                l.display()
            )),
            build.join(" ")
        ));
        let child = cmd
            .spawn()
            .map_err(|e| format!("cannot start cargo: {e}"))?;
        Ok(Build { child, log })
    }

    /// Waits for the build; its error names the compiler's messages.
    pub fn finish(mut self) -> Result<(), String> {
        let status = self
            .child
            .wait()
            .map_err(|e| format!("the fuzz targets' build: {e}"))?;
        if status.success() {
            return Ok(());
        }
        let messages = match &self.log {
            Some(log) => {
                let text = std::fs::read_to_string(log).unwrap_or_default();
                let tail: Vec<&str> = text.lines().rev().take(40).collect();
                let tail: Vec<&str> = tail.into_iter().rev().collect();
                format!("in {}:\n{}", log.display(), tail.join("\n"))
            }
            None => "above".into(),
        };
        Err(format!(
            "building the fuzz targets failed ({status}): the compiler's messages are {messages}\n\
             (libFuzzer itself needs a C++ compiler, `c++`: Debian's g++, which `cargo xtask \
             setup` installs)"
        ))
    }

    /// Stops the build (the tests beside it failed).
    pub fn stop(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs each of the built targets ([`Build`]) for `secs` seconds.
pub fn run_built(targets: &[&'static str], secs: u32) -> Result<(), String> {
    let (root, out) = dirs();
    let host = host_triple()?;
    let bin_dir = out.join(&host).join("release");
    let mut figures = Vec::new();
    for lane in lanes(targets) {
        // each target of a lane on its own core, for its full `secs` (libFuzzer's loop is
        // one thread; the diagnosis's own threads take both cores, so it runs alone)
        let done: Vec<Result<Figures, String>> = std::thread::scope(|s| {
            let runs: Vec<_> = lane
                .iter()
                .map(|&(i, t)| {
                    let (root, out, bin_dir) = (&root, &out, &bin_dir);
                    s.spawn(move || run_one(root, out, bin_dir, t, secs, 1 + i as u64))
                })
                .collect();
            runs.into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err("a fuzz run panicked".into()))
                })
                .collect()
        });
        for (&(i, _), f) in lane.iter().zip(done) {
            figures.push((i, f?));
        }
    }
    figures.sort_by_key(|f| f.0);
    let figures: Vec<Figures> = figures.into_iter().map(|f| f.1).collect();
    let table = summary(&figures);
    println!("{table}");
    let json = out.join("summary.json");
    std::fs::write(&json, summary_json(&figures))
        .map_err(|e| format!("cannot write {}: {e}", json.display()))?;
    say(&format!("written {}", json.display()));
    Ok(())
}

fn run_one(
    root: &Path,
    out: &Path,
    bin_dir: &Path,
    target: &'static str,
    secs: u32,
    seed: u64,
) -> Result<Figures, String> {
    let scratch = out.join("corpus").join(target);
    let artifacts = out.join("artifacts").join(target);
    for d in [&scratch, &artifacts] {
        std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))?;
    }
    let mut dirs: Vec<PathBuf> = vec![scratch];
    let fuzz = root.join("tests/fuzz");
    dirs.push(fuzz.join("seeds").join(target));
    if target == "scenario_parser" {
        dirs.push(root.join("host-sim/scenarios"));
    }
    dirs.push(fuzz.join("regressions").join(target));
    dirs.retain(|d| d.is_dir());
    let bin = bin_dir.join(target);
    let mut args = vec![
        format!("-max_total_time={secs}"),
        format!("-seed={seed}"),
        "-timeout=10".into(),
        "-rss_limit_mb=2048".into(),
        "-print_final_stats=1".into(),
        format!("-artifact_prefix={}/", artifacts.display()),
    ];
    args.extend(dirs.iter().map(|d| d.display().to_string()));
    say(&format!(
        "fuzzing {target} for {secs} s: {} {}",
        bin.display(),
        args.join(" ")
    ));
    let o = Command::new(&bin)
        .args(&args)
        .output()
        .map_err(|e| format!("cannot start {}: {e}", bin.display()))?;
    // libFuzzer reports on stderr
    let log = String::from_utf8_lossy(&o.stderr);
    std::fs::write(out.join(format!("{target}.log")), log.as_bytes())
        .map_err(|e| format!("cannot write the {target} log: {e}"))?;
    if !o.status.success() {
        let tail: Vec<&str> = log.lines().rev().take(30).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        let saved: Vec<String> = std::fs::read_dir(&artifacts)
            .map(|rd| {
                rd.filter_map(|e| Some(e.ok()?.path().display().to_string()))
                    .collect()
            })
            .unwrap_or_default();
        return Err(format!(
            "libFuzzer failed on {target} ({}):\n{}\nsaved input(s): {}\nadd the input to \
             tests/fuzz/regressions/{target}/ with the fix; the run replays it from then on",
            o.status,
            tail.join("\n"),
            if saved.is_empty() {
                "none".into()
            } else {
                saved.join(", ")
            }
        ));
    }
    let runs = stat(&log, "stat::number_of_executed_units:");
    let (cov, corpus) = last_status(&log);
    match runs {
        Some(runs) if runs > 0 => Ok(Figures {
            target,
            runs,
            cov,
            corpus,
            secs,
        }),
        _ => Err(format!(
            "libFuzzer ran {target} but reported no executed inputs (log: {})",
            out.join(format!("{target}.log")).display()
        )),
    }
}

/// `rustc -vV`'s `host:` line.
fn host_triple() -> Result<String, String> {
    let v = crate::output("rustc", &["-vV"])?;
    v.lines()
        .find_map(|l| l.strip_prefix("host: "))
        .map(|s| s.trim().to_string())
        .ok_or_else(|| "`rustc -vV` names no host triple".into())
}

/// The value after `key` on its line of the final statistics.
fn stat(log: &str, key: &str) -> Option<u64> {
    log.lines()
        .find_map(|l| l.trim().strip_prefix(key))
        .and_then(|v| v.trim().parse().ok())
}

/// `cov:` and `corp:` of libFuzzer's last status line (`#N DONE cov: C ft: F corp: K/…`).
fn last_status(log: &str) -> (u64, u64) {
    let field = |l: &str, key: &str| -> Option<u64> {
        let rest = l.split(key).nth(1)?;
        let num: String = rest
            .trim_start()
            .chars()
            .take_while(char::is_ascii_digit)
            .collect();
        num.parse().ok()
    };
    log.lines()
        .rev()
        .find_map(|l| {
            if l.starts_with('#') && l.contains(" cov: ") {
                Some((field(l, " cov: ")?, field(l, " corp: ").unwrap_or(0)))
            } else {
                None
            }
        })
        .unwrap_or((0, 0))
}

fn summary(f: &[Figures]) -> String {
    let mut s = String::from(
        "| target (libFuzzer, stable, no sanitizer) | seconds | runs | coverage (edges) | corpus | crashes |\n\
         |---|---|---|---|---|---|\n",
    );
    for x in f {
        let _ = writeln!(
            s,
            "| `{}` | {} | {} | {} | {} | 0 |",
            x.target, x.secs, x.runs, x.cov, x.corpus
        );
    }
    s
}

fn summary_json(f: &[Figures]) -> String {
    let rows: Vec<String> = f
        .iter()
        .map(|x| {
            format!(
                "  {{\"target\": \"{}\", \"secs\": {}, \"runs\": {}, \"cov\": {}, \"corpus\": {}, \"crashes\": 0}}",
                x.target, x.secs, x.runs, x.cov, x.corpus
            )
        })
        .collect();
    format!("[\n{}\n]\n", rows.join(",\n"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_libfuzzer_figures() {
        let log = "INFO: Seed: 1\n#2\tINITED cov: 12 ft: 13 corp: 1/30b exec/s: 0 rss: 30Mb\n\
                   #4096\tpulse  cov: 40 ft: 60 corp: 7/210b lim: 43 exec/s: 2048 rss: 31Mb\n\
                   #69711\tDONE   cov: 41 ft: 61 corp: 8/240b lim: 43 exec/s: 1742 rss: 31Mb\n\
                   Done 69711 runs in 41 second(s)\n\
                   stat::number_of_executed_units: 69711\nstat::average_exec_per_sec:     1700\n";
        assert_eq!(stat(log, "stat::number_of_executed_units:"), Some(69_711));
        assert_eq!(last_status(log), (41, 8));
        assert_eq!(stat("no stats\n", "stat::number_of_executed_units:"), None);
        assert_eq!(last_status("nothing"), (0, 0));
    }

    #[test]
    fn pairs_single_threaded_targets_and_runs_the_diagnosis_alone() {
        let l = lanes(&TARGETS);
        assert_eq!(
            l,
            vec![
                vec![(0, "ads131m08_frame"), (1, "record_reader")],
                vec![(2, "scenario_parser"), (3, "estimator_step")],
                vec![(4, "diagnosis")],
            ]
        );
        let l = lanes(&["diagnosis", "record_reader"]);
        assert_eq!(l, vec![vec![(0, "diagnosis")], vec![(1, "record_reader")]]);
    }

    #[test]
    fn refuses_unknown_targets_and_bad_seconds() {
        let e = fuzz(&["nope".into()]).unwrap_err();
        assert!(e.contains("unknown fuzz target `nope`"), "{e}");
        let e = fuzz(&["--secs".into(), "0".into()]).unwrap_err();
        assert!(e.contains("not a positive"), "{e}");
        let e = fuzz(&["--secs".into()]).unwrap_err();
        assert!(e.contains("needs a number"), "{e}");
    }
}
