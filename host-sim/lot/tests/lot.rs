//! A small lot end to end: four records made with the simulator (a clean device, one with
//! an effect, a device whose record is too short to diagnose, one with a temperature ramp),
//! a corrupt file and a truth file in the folder. Checked: the rows come back in the
//! folder's order, the corrupt file is one error row (with its path), every value of a
//! row is report.json's (bit for bit), the Parquet file reads back to the same rows, and
//! the lot report's files exist with links that resolve.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use paragyro_diagnose::diagnose::calibrate::PARAM_NAMES;
use paragyro_diagnose::diagnose::{Options, Report};
use paragyro_lot::row::TIMING_STAGES;
use paragyro_lot::{
    LotOptions, LotRow, Spec, diagnose_lot, find_records, read_parquet, report, write_parquet,
};
use paragyro_simulator::record::{RecordOptions, write_simulated_record};
use paragyro_simulator::scenario::Scenario;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("paragyro-lot-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes `dir/name.csv` (and its truth) from `characterise` cut to `duration_s`.
fn record(dir: &Path, name: &str, duration_s: f64, opts: RecordOptions) {
    let mut sc = Scenario::load("characterise").unwrap();
    sc.duration_s = duration_s;
    write_simulated_record(&sc, &dir.join(format!("{name}.csv")), &opts, &mut |_| {}).unwrap();
}

fn make_lot(dir: &Path) {
    let table = |seed| RecordOptions {
        seed: Some(seed),
        rate_table: true,
        ..RecordOptions::default()
    };
    record(dir, "a-clean", 4.0, table(5));
    record(
        dir,
        "b-damping",
        4.0,
        RecordOptions {
            effects: vec!["nonlinear_damping=6e-6".parse().unwrap()],
            ..table(27)
        },
    );
    std::fs::write(dir.join("c-corrupt.csv"), "this is not a record\n1,2,3\n").unwrap();
    record(dir, "d-short", 1.5, table(6));
    record(
        dir,
        "e-warm",
        4.0,
        RecordOptions {
            temp: Some((25.0, 2.0)),
            ..table(8)
        },
    );
}

/// Every column of `row` against report.json, bit for bit.
fn check_against_report_json(row: &LotRow, r: &Report) {
    let name = &row.record;
    let same = |what: &str, a: Option<f64>, b: Option<f64>| {
        assert_eq!(
            a.map(f64::to_bits),
            b.map(f64::to_bits),
            "{name}: {what}: row {a:?}, report.json {b:?}"
        );
    };
    assert_eq!(row.verdict.as_deref(), Some(r.verdict.to_string().as_str()));
    assert_eq!(
        row.secondary,
        r.verdict.secondary().map(|s| s.effect.to_string())
    );
    assert_eq!(row.samples, Some(r.samples as i64));
    same("gap_before", row.gap_before, Some(r.gap_before));
    same("gap_after", row.gap_after, Some(r.gap_after));
    same("gap_closure", row.gap_closure, Some(r.gap_closure));
    same(
        "unexplained_above_noise",
        row.unexplained_above_noise,
        Some(r.unexplained_above_noise),
    );
    same(
        "residual_over_noise",
        row.residual_over_noise,
        Some(r.residual_over_noise),
    );
    same(
        "noise",
        row.noise_energy_ratio,
        Some(r.parameter_face.noise_energy_ratio),
    );
    same("seconds", row.seconds, Some(r.seconds));
    let t = &r.location.time;
    same(
        "where.time[0]",
        row.where_time_half_from_s,
        Some(t.half_of_gap_within_s[0]),
    );
    same(
        "where.time[1]",
        row.where_time_half_to_s,
        Some(t.half_of_gap_within_s[1]),
    );
    same(
        "cusum",
        row.where_time_cusum_extreme_s,
        Some(t.cusum_extreme_at_s),
    );
    let top: Vec<_> = r
        .ranking
        .iter()
        .filter(|c| c.untestable.is_none())
        .collect();
    let slots = [
        (
            &row.top1_effect,
            row.top1_size,
            row.top1_sigma,
            row.top1_gap_closure,
        ),
        (
            &row.top2_effect,
            row.top2_size,
            row.top2_sigma,
            row.top2_gap_closure,
        ),
        (
            &row.top3_effect,
            row.top3_size,
            row.top3_sigma,
            row.top3_gap_closure,
        ),
    ];
    for (i, (e, size, sigma, gc)) in slots.into_iter().enumerate() {
        let c = top.get(i);
        assert_eq!(
            e.clone(),
            c.map(|c| c.effect.to_string()),
            "{name}: top{}",
            i + 1
        );
        same("size", size, c.and_then(|c| c.size));
        same("sigma", sigma, c.and_then(|c| c.size_sigma));
        same("gap closure", gc, c.map(|c| c.gap_closure));
    }
    let face = &r.parameter_face.parameters;
    for p in PARAM_NAMES {
        match (row.param(p), face.iter().find(|q| q.name == p)) {
            (Some(v), Some(q)) => {
                same(p, Some(v.model), Some(q.model));
                same(p, Some(v.device), Some(q.device));
                same(p, Some(v.sigma), Some(q.sigma));
                same(p, v.rel, q.relative);
                same(p, v.rel_sigma, q.relative_sigma);
                same(p, Some(v.t), Some(q.t));
            }
            (None, None) => {}
            (a, b) => panic!("{name}: {p}: row {a:?}, report.json {b:?}"),
        }
    }
    for s in TIMING_STAGES {
        same(s, row.stage_seconds(s), r.timing_s.get(s).copied());
    }
}

/// Markdown link targets of `md` (`](target)` and `](<target>)`), web links left out.
fn links(md: &str) -> Vec<String> {
    md.split("](")
        .skip(1)
        .filter_map(|rest| {
            let t = if let Some(r) = rest.strip_prefix('<') {
                r.split('>').next()
            } else {
                rest.split(')').next()
            }?;
            (!t.starts_with("http")).then(|| t.to_string())
        })
        .collect()
}

#[test]
fn a_small_lot_end_to_end() {
    let dir = tmp("e2e");
    let lot = dir.join("lot");
    std::fs::create_dir_all(&lot).unwrap();
    make_lot(&lot);
    std::fs::write(lot.join("a-clean.truth.csv"), "not a record either").unwrap();
    let paths = find_records(&lot).unwrap();
    let names: Vec<String> = paths
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        names,
        [
            "a-clean.csv",
            "b-damping.csv",
            "c-corrupt.csv",
            "d-short.csv",
            "e-warm.csv"
        ],
        "sorted, truth files skipped"
    );
    let opts = LotOptions {
        diagnose: Options {
            resimulate: false,
            ..Options::default()
        },
        reports: Some(dir.join("reports")),
        threads: 2,
    };
    let seen = Mutex::new(Vec::new());
    let rows = diagnose_lot(&paths, &opts, &|done, total, row| {
        assert_eq!(total, 5);
        seen.lock().unwrap().push((done, row.record.clone()));
    })
    .unwrap();
    let mut seen = seen.into_inner().unwrap();
    seen.sort();
    assert_eq!(
        seen.iter().map(|s| s.0).collect::<Vec<_>>(),
        [1, 2, 3, 4, 5]
    );
    let got: Vec<&str> = rows.iter().map(|r| r.record.as_str()).collect();
    assert_eq!(got, names, "the rows in input order");

    // the corrupt file: one row, its error with the path, nothing else
    let bad = &rows[2];
    let err = bad.error.as_deref().expect("an error row");
    assert!(err.contains(&paths[2].display().to_string()), "{err}");
    assert_eq!(
        (bad.verdict.as_ref(), bad.samples, bad.values.len()),
        (None, None, 0)
    );
    for (i, row) in rows.iter().enumerate().filter(|(i, _)| *i != 2) {
        assert!(row.error.is_none(), "{:?}", row.error);
        let rd = PathBuf::from(row.report_dir.as_ref().unwrap());
        let text = std::fs::read_to_string(rd.join("report.json")).unwrap();
        let r: Report = serde_json::from_str(&text).unwrap();
        check_against_report_json(row, &r);
        assert_eq!(row.path, paths[i].display().to_string());
    }
    // the short record: diagnosed as `unknown`, its reason a limitation, no parameters
    assert_eq!(rows[3].verdict.as_deref(), Some("unknown"));
    assert!(
        rows[3]
            .limitations
            .as_deref()
            .unwrap()
            .starts_with("record: ")
    );
    assert!(rows[3].param("wy2").is_none());
    // the others are calibrated: every parameter
    assert!(PARAM_NAMES.iter().all(|p| rows[0].param(p).is_some()));

    // Parquet round trip
    let pq = dir.join("lot.parquet");
    write_parquet(&pq, &rows).unwrap();
    let back = read_parquet(&pq).unwrap();
    assert_eq!(back, rows);

    // the lot report: a spec nobody meets (wy2 above +1), so every diagnosed device is an
    // outlier with a link to its report
    let spec = Spec::parse(
        "name = \"e2e\"\n[parameters.wy2]\nlo = 1.0\n[parameters.mu_x]\nlo = -0.5\nhi = 0.5\n",
    )
    .unwrap();
    let out = dir.join("report");
    let s = report(&back, &spec, &out).unwrap();
    assert_eq!(s.errors.len(), 1);
    assert_eq!(s.outliers.len(), 4);
    assert_eq!(s.yield_.passed, 0);
    assert_eq!(s.yield_.diagnosed, 4);
    assert_eq!(s.verdicts.values().sum::<usize>(), 4);
    let md = std::fs::read_to_string(out.join("lot.md")).unwrap();
    assert!(out.join("lot.json").is_file());
    let targets = links(&md);
    let reports = targets.iter().filter(|t| t.ends_with("report.md")).count();
    assert_eq!(reports, 4, "{md}");
    assert!(targets.iter().any(|t| t == "dev_wy2.png"), "{md}");
    for t in &targets {
        assert!(
            out.join(t).is_file(),
            "lot.md links {t}, which is not there"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A path that cannot be read is an error row with its path (no panic, no abort), and a
/// lot of only such paths still gives a row each.
#[test]
fn unreadable_paths_are_error_rows() {
    let dir = tmp("unreadable");
    let paths = vec![dir.join("missing.csv"), dir.clone()];
    let rows = diagnose_lot(&paths, &LotOptions::default(), &|_, _, _| {}).unwrap();
    assert_eq!(rows.len(), 2);
    for (r, p) in rows.iter().zip(&paths) {
        let e = r.error.as_deref().unwrap();
        assert!(e.contains(&p.display().to_string()), "{e}");
    }
    let pq = dir.join("errors.parquet");
    write_parquet(&pq, &rows).unwrap();
    assert_eq!(read_parquet(&pq).unwrap(), rows);
    let _ = std::fs::remove_dir_all(&dir);
}
