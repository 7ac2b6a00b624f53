//! The generator's output: records the project reads, labels the blind benchmark reads,
//! written after the records, the same bytes for the same seed, and draws in the blind
//! benchmark's proportions.

use std::path::{Path, PathBuf};

use paragyro_refsim::effects::{Effect, LIBRARY};
use paragyro_refsim::generate::{Category, GenOptions, Labels, SHARES, draw, generate};

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("refsim-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn opts(n: usize, seed: u64) -> GenOptions {
    GenOptions {
        n,
        seed,
        duration_s: 0.4,
        lpf: (4, 150.0),
        pump_amp_ref_v: 1.0,
        rtol: 1e-9,
        reversal_share: 0.4,
        only: Vec::new(),
        category: None,
    }
}

fn gen_into(dir: &Path, n: usize, seed: u64) -> paragyro_refsim::generate::GenReport {
    generate(&opts(n, seed), dir, &|_| {}).unwrap()
}

/// Records read back with the project's reader (header, columns, rows, the optional
/// columns); labels.json is written after every record and reads as the blind
/// benchmark's own `Labels`.
#[test]
fn records_read_back_and_labels_come_last() {
    let dir = out_dir("read");
    let rep = gen_into(&dir, 3, 7);
    let labels_time = std::fs::metadata(&rep.labels).unwrap().modified().unwrap();
    let text = std::fs::read_to_string(&rep.labels).unwrap();
    let mine: Labels = serde_json::from_str(&text).unwrap();
    let theirs: paragyro_diagnose::blind::Labels = serde_json::from_str(&text).unwrap();
    assert_eq!(theirs.records.len(), 3);
    assert_eq!(theirs.seed, 7);
    for (i, path) in rep.records.iter().enumerate() {
        assert!(std::fs::metadata(path).unwrap().modified().unwrap() <= labels_time);
        let rec = paragyro_simulator::record::read_record(path).unwrap();
        assert!(rec.warnings.is_empty(), "{:?}", rec.warnings);
        assert_eq!(rec.rows.len(), 201);
        let h = &rec.header;
        assert_eq!(
            (h.fs_hz, h.lockin_lpf_order, h.lockin_lpf_hz),
            (500.0, 4, 150.0)
        );
        assert!((h.f0_hz - 10_799.814_442_720_044).abs() < 1e-9);
        let d = &mine.records[i];
        assert_eq!(path.file_name().unwrap().to_str().unwrap(), d.file);
        assert_eq!(theirs.records[i].id, d.id);
        assert_eq!(theirs.records[i].device.deviations, d.device.deviations);
        let last = rec.rows.last().unwrap();
        assert!(last.temp_c.is_some() && last.rate_ref_dps.is_some());
        // the rate table's rate: the drawn rate, reversed by the end if the record has a
        // reversal
        let sign = if d.protocol.reversal.is_some() {
            -1.0
        } else {
            1.0
        };
        assert!((last.rate_ref_dps.unwrap() - sign * d.device.rate_dps).abs() < 1e-9);
        assert!(
            last.lockin.x_um[0].re.hypot(last.lockin.x_um[0].im) > 0.1,
            "{}: the drive did not start",
            d.id
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The same seed gives the same files, byte for byte; another seed other records.
#[test]
fn the_generator_is_deterministic() {
    let (a, b, c) = (out_dir("a"), out_dir("b"), out_dir("c"));
    gen_into(&a, 2, 5);
    gen_into(&b, 2, 5);
    gen_into(&c, 2, 6);
    for f in ["0000.csv", "0001.csv", "labels.json"] {
        let ra = std::fs::read(a.join(f)).unwrap();
        assert_eq!(ra, std::fs::read(b.join(f)).unwrap(), "{f}");
        assert_ne!(ra, std::fs::read(c.join(f)).unwrap(), "{f}");
    }
    for d in [a, b, c] {
        std::fs::remove_dir_all(&d).unwrap();
    }
}

/// The draw: the blind benchmark's category shares, every library effect drawn, sizes
/// within their ranges, the thermal drift negative, the softening pump-driven.
#[test]
fn draws_have_the_blind_benchmarks_proportions() {
    let draws = draw(2000, 3, 20.0, 0.4);
    let share = |c: Category| draws.iter().filter(|d| d.category == c).count() as f64 / 2000.0;
    let want = [
        SHARES[0],
        SHARES[1] - SHARES[0],
        SHARES[2] - SHARES[1],
        1.0 - SHARES[2],
    ];
    let got = [
        share(Category::None),
        share(Category::Single),
        share(Category::Double),
        share(Category::Outside),
    ];
    for (g, w) in got.iter().zip(want) {
        assert!((g - w).abs() < 0.035, "{got:?} vs {want:?}");
    }
    for e in LIBRARY {
        assert!(
            draws
                .iter()
                .any(|d| d.effects.iter().any(|s| s.effect == e)),
            "{e}"
        );
    }
    let reversals = draws
        .iter()
        .filter(|d| d.protocol.reversal.is_some())
        .count();
    assert!((600..1000).contains(&reversals), "{reversals} reversals");
    for d in &draws {
        for s in &d.effects {
            let r = s.effect.size_range();
            assert!((r.low..=r.high).contains(&s.size.abs()), "{s:?}");
            match s.effect {
                Effect::ThermalDrift => assert!(s.size < 0.0),
                Effect::ElectrostaticSoftening => assert_eq!(s.param, Some(1.0)),
                Effect::AngularVibration => {
                    assert!((0.5..=5.0).contains(&s.param.unwrap().abs()))
                }
                _ => {}
            }
        }
        let inside = d.effects.iter().all(|s| LIBRARY.contains(&s.effect));
        let outside = d.outside.is_some() || !inside;
        assert_eq!(d.category == Category::Outside, outside, "{}", d.id);
    }
}

/// A bad argument is an error that says what is wrong, and writes nothing.
#[test]
fn bad_options_are_clear_errors() {
    let dir = out_dir("bad");
    let e = generate(&GenOptions { n: 0, ..opts(1, 1) }, &dir, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("--n"), "{e}");
    let e = generate(
        &GenOptions {
            duration_s: 0.0,
            ..opts(1, 1)
        },
        &dir,
        &|_| {},
    )
    .unwrap_err();
    assert!(e.to_string().contains("--duration-s"), "{e}");
    assert!(!dir.join("labels.json").exists());
}

/// `--only` and `--category` write a subset of the same draw: each record kept is the
/// same bytes as in the full run, labels.json holds exactly the kept ones, and an id that
/// was not drawn is an error.
#[test]
fn a_selection_writes_the_full_runs_records() {
    let (n, seed) = (8, 11);
    let full = out_dir("sel-full");
    gen_into(&full, n, seed);
    let all = draw(n, seed, 0.4, 0.4);
    let labels_of = |dir: &Path| -> Labels {
        serde_json::from_str(&std::fs::read_to_string(dir.join("labels.json")).unwrap()).unwrap()
    };
    let same_bytes = |dir: &Path, id: &str| {
        let name = format!("{id}.csv");
        std::fs::read(dir.join(&name)).unwrap() == std::fs::read(full.join(&name)).unwrap()
    };

    let only = out_dir("sel-only");
    let ids = vec!["0006".to_string(), "0002".to_string()];
    let rep = generate(
        &GenOptions {
            only: ids.clone(),
            ..opts(n, seed)
        },
        &only,
        &|_| {},
    )
    .unwrap();
    assert_eq!(rep.records.len(), 2);
    let kept: Vec<String> = labels_of(&only).records.into_iter().map(|d| d.id).collect();
    assert_eq!(kept, ["0002", "0006"]);
    assert!(ids.iter().all(|id| same_bytes(&only, id)));
    assert!(!only.join("0000.csv").exists());

    let cat = all[0].category;
    let by_cat = out_dir("sel-cat");
    generate(
        &GenOptions {
            category: Some(cat),
            ..opts(n, seed)
        },
        &by_cat,
        &|_| {},
    )
    .unwrap();
    let want: Vec<&str> = all
        .iter()
        .filter(|d| d.category == cat)
        .map(|d| d.id.as_str())
        .collect();
    let got = labels_of(&by_cat).records;
    assert_eq!(got.iter().map(|d| d.id.as_str()).collect::<Vec<_>>(), want);
    assert!(want.iter().all(|id| same_bytes(&by_cat, id)));

    let e = generate(
        &GenOptions {
            only: vec!["0008".into()],
            ..opts(n, seed)
        },
        &out_dir("sel-bad"),
        &|_| {},
    )
    .unwrap_err();
    assert!(e.to_string().contains("--only 0008"), "{e}");
    for d in [full, only, by_cat] {
        let _ = std::fs::remove_dir_all(d);
    }
}
