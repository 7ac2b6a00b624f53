//! The command line end to end: parsing, exit codes, messages, files written.

use super::*;
use crate::cmd::{EXIT_LOAD, PrecisionArg};
use paragyro_simulator::scenario::Scenario;
use std::path::Path;

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
    let path = std::env::temp_dir().join(format!("paragyro-cli-bad-{}.toml", std::process::id()));
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
        Command::Run(a) => {
            assert_eq!(a.precision, PrecisionArg::F32);
            assert_eq!(a.seed, None);
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
        Command::Run(cmd::run::Args {
            seed: Some(7),
            precision: PrecisionArg::F64,
            ..
        })
    ));
    let c = Cli::try_parse_from(["paragyro-sim", "demo"]).unwrap();
    assert!(matches!(c.command, Command::Demo(ref a) if a.out == Path::new("out")));
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

/// `lot` on a folder of one short record and one corrupt file: exit 0, the corrupt file an
/// error row, the Parquet, the device's report and the lot report written; `lot-report`
/// redraws the report from the Parquet. A folder with nothing readable exits 2 (still with
/// its rows), one without records too.
#[test]
fn lot_then_lot_report() {
    let dir = std::env::temp_dir().join(format!("paragyro-cli-lot-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let lot = dir.join("lot");
    std::fs::create_dir_all(&lot).unwrap();
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = 4.0;
    let opts = paragyro_simulator::record::RecordOptions {
        seed: Some(5),
        rate_table: true,
        ..Default::default()
    };
    paragyro_simulator::record::write_simulated_record(
        &sc,
        &lot.join("dev-1.csv"),
        &opts,
        &mut |_| {},
    )
    .unwrap();
    std::fs::write(lot.join("dev-2.csv"), "garbage\n").unwrap();
    let pq = dir.join("lot.parquet");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (code, out, err) = cli(&[
        "lot",
        &s(&lot),
        "--out",
        &s(&pq),
        "--reports",
        &s(&dir.join("reports")),
        "--report",
        &s(&dir.join("report")),
        "--jobs",
        "2",
        "--no-resim",
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("2 records in "), "{out}");
    assert!(out.contains(": 1 diagnosed, 1 errors\n"), "{out}");
    assert!(dir.join("reports/dev-1/report.md").is_file());
    assert!(dir.join("report/lot.md").is_file());
    let rows = paragyro_lot::read_parquet(&pq).unwrap();
    assert_eq!(rows.len(), 2);
    assert!(rows[1].error.as_deref().unwrap().contains("dev-2.csv"));
    let spec = dir.join("spec.toml");
    std::fs::write(&spec, "[parameters.wy2]\nlo = -0.01\nhi = 0.01\n").unwrap();
    let (code, out, err) = cli(&[
        "lot-report",
        &s(&pq),
        "--spec",
        &s(&spec),
        "--out",
        &s(&dir.join("again")),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("2 devices read from "), "{out}");
    assert!(dir.join("again/lot.md").is_file() && dir.join("again/dev_wy2.png").is_file());
    // a bad spec: exit 2 with the file's name
    std::fs::write(&spec, "[parameters.wy9]\nhi = 1\n").unwrap();
    let (code, _, err) = cli(&[
        "lot-report",
        &s(&pq),
        "--spec",
        &s(&spec),
        "--out",
        &s(&dir),
    ]);
    assert_eq!(code, EXIT_LOAD);
    assert!(err.contains("spec.toml") && err.contains("wy9"), "{err}");
    // nothing readable: exit 2, the rows still written
    std::fs::remove_file(lot.join("dev-1.csv")).unwrap();
    let (code, _, err) = cli(&["lot", &s(&lot), "--out", &s(&pq)]);
    assert_eq!(code, EXIT_LOAD);
    assert!(err.contains("none of the 1 records"), "{err}");
    assert_eq!(paragyro_lot::read_parquet(&pq).unwrap().len(), 1);
    // no record at all
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    let (code, _, err) = cli(&["lot", &s(&empty), "--out", &s(&pq)]);
    assert_eq!(code, EXIT_LOAD);
    assert!(err.contains("no record"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
