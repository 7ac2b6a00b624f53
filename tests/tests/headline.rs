//! The front page's headline table (`README.md`, between `<!-- headline:begin -->` and
//! `<!-- headline:end -->`) against the sources its rows name: every number of a row's
//! value must be a number the source gives. One source per figure, so the figures cannot
//! drift apart (tests/README.md, "The headline table").
//!
//! * `paragyro-sim -- results`: regenerated here (`paragyro_simulator::results`, every
//!   built-in scenario in f32 and f64, seconds at the test profile);
//! * `paragyro-fil -- budget`: the budgets are `paragyro_fil::budget`'s constants; the
//!   measured flash, RAM and tick need the thumb build and QEMU (`.ci/run`), so they are
//!   checked against the artifacts that run leaves (`target/paragyro-firmware-stm32f405.elf`,
//!   `target/fil/summary.json`) when `PARAGYRO_FW_FIGURES=1` is set;
//! * `paragyro-sim -- rate-response`: the chirp, the step and the ramp of that report
//!   regenerated here (`paragyro_simulator::rate_response`, f32, seed 1; seconds), with the
//!   precision the table shows;
//! * `paragyro-refsim --example score -- out/refsim-3333`: the results of blind run 31,
//!   pooled with run 30, as committed in `host-sim/diagnose/blind-benchmark.md`
//!   (generating and diagnosing 100 records takes most of an hour).
//!
//! And the results table of `host-sim/README.md` is `paragyro-sim results`' table, cell
//! for cell but the wall times.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

fn read(rel: &str) -> String {
    fs::read_to_string(root().join(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// `paragyro-sim results`' table, regenerated once per test run.
fn results() -> &'static str {
    static TABLE: OnceLock<String> = OnceLock::new();
    TABLE.get_or_init(|| paragyro_simulator::results::results_table(&mut |_| {}).expect("results"))
}

/// The first three cells (scenario, core, result) of each row of a results table.
fn result_rows(table: &str) -> Vec<[String; 3]> {
    table
        .lines()
        .filter(|l| l.starts_with("| `"))
        .map(|l| {
            let c: Vec<&str> = l.trim_matches('|').split(" | ").map(str::trim).collect();
            [c[0].to_string(), c[1].to_string(), c[2].to_string()]
        })
        .collect()
}

/// (figure, value, source) of each row of the README's headline table.
fn headline_rows(readme: &str) -> Vec<(String, String, String)> {
    let begin = readme
        .find("<!-- headline:begin -->")
        .expect("README.md has <!-- headline:begin -->");
    let end = readme
        .find("<!-- headline:end -->")
        .expect("README.md has <!-- headline:end -->");
    readme[begin..end]
        .lines()
        .filter(|l| l.starts_with('|') && !l.starts_with("|---") && !l.starts_with("| figure"))
        .map(|l| {
            let cells: Vec<String> = l
                .trim()
                .trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_string())
                .collect();
            assert_eq!(
                cells.len(),
                3,
                "headline row with {} cells: {l}",
                cells.len()
            );
            (cells[0].clone(), cells[1].clone(), cells[2].clone())
        })
        .collect()
}

/// The numbers of a text as written: `65 416`, `0.48`, `12 000` (groups of three digits
/// after a space belong to the number); digits glued to a letter (`θ14`, `f32`) are names,
/// not numbers.
fn numbers(text: &str) -> Vec<String> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let glued = i > 0 && (c[i - 1].is_alphabetic() || c[i - 1] == '_');
        if !c[i].is_ascii_digit() || glued {
            // skip the rest of a name
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            i += usize::from(i < c.len() && !c[i].is_ascii_digit());
            continue;
        }
        let start = i;
        loop {
            while i < c.len() && (c[i].is_ascii_digit() || c[i] == '.') {
                i += 1;
            }
            // `65 416`: a space and exactly three digits
            let group = i + 4 <= c.len()
                && c[i] == ' '
                && c[i + 1..i + 4].iter().all(char::is_ascii_digit)
                && (i + 4 == c.len() || !c[i + 4].is_ascii_digit());
            if group {
                i += 4;
            } else {
                break;
            }
        }
        let n: String = c[start..i].iter().collect();
        out.push(n.trim_end_matches('.').to_string());
    }
    out
}

/// `65536` → `65 536`.
fn grouped(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (k, ch) in s.chars().enumerate() {
        if k > 0 && (s.len() - k).is_multiple_of(3) {
            out.push(' ');
        }
        out.push(ch);
    }
    out
}

/// The numbers of `value` that `source` does not give.
fn missing(value: &str, source: &str) -> Vec<String> {
    let have = numbers(source);
    numbers(value)
        .into_iter()
        .filter(|n| !have.contains(n))
        .collect()
}

/// The firmware's budgets, and with `PARAGYRO_FW_FIGURES=1` the measured figures from the
/// artifacts `.ci/run` leaves.
fn budget_source() -> (String, bool) {
    use paragyro_fil::budget as bu;
    let mut s = format!(
        "budgets {} {} {} {}",
        grouped(bu::FLASH_BUDGET),
        grouped(bu::RAM_BUDGET),
        grouped(bu::TICK_MEAN_TARGET as u64),
        grouped(bu::TICK_MAX_TARGET)
    );
    if std::env::var("PARAGYRO_FW_FIGURES").as_deref() != Ok("1") {
        return (s, false);
    }
    let elf = root().join("target/paragyro-firmware-stm32f405.elf");
    let summary = root().join("target/fil/summary.json");
    let elf = fs::read(&elf).unwrap_or_else(|e| panic!("{}: {e} (bash .ci/run)", elf.display()));
    let summary = fs::read_to_string(&summary)
        .unwrap_or_else(|e| panic!("{}: {e} (cargo fw-loop)", summary.display()));
    let (flash, ram_static) = paragyro_fil::elf::flash_and_ram(&elf).expect("the image's sizes");
    let stack_peak = json_number(&summary, "stack_peak_bytes") as u64;
    let instr_mean = json_number(&summary, "instr_mean");
    let instr_max = json_number(&summary, "instr_max") as u64;
    s += &format!(
        " measured {} {} {} {}",
        grouped(flash),
        grouped(ram_static + stack_peak),
        grouped(instr_mean.round() as u64),
        grouped(instr_max)
    );
    (s, true)
}

/// The number after `"key":` in a JSON text (a test's reading of the loop's summary; the
/// tests crate has no JSON parser).
fn json_number(text: &str, key: &str) -> f64 {
    let k = format!("\"{key}\":");
    let at = text
        .find(&k)
        .unwrap_or_else(|| panic!("summary.json has no {key}"))
        + k.len();
    let v: String = text[at..]
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | 'E' | '+'))
        .collect();
    v.parse()
        .unwrap_or_else(|e| panic!("summary.json {key}: {v}: {e}"))
}

/// The rate channel's bandwidth (Hz), the step's largest error after 25 ms (% of the
/// step), the ramp's scale-factor error (ppm) and nonlinearity (ppm FS), as the datasheet
/// rounds them: what `paragyro-sim rate-response` measures (f32, seed 1).
/// What `paragyro-sim thermal` (its default, the warm-up scenario) prints: its report.
fn thermal_source() -> String {
    use paragyro_simulator::runner::{Precision, RunOptions, run};
    use paragyro_simulator::scenario::Scenario;
    use paragyro_simulator::thermal::ThermalReport;
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../host-sim/scenarios/warm-up.toml"
    );
    let sc = Scenario::from_file(std::path::Path::new(path)).expect("warm-up.toml");
    let opts = RunOptions {
        precision: Precision::F32,
        seed: None,
    };
    let r = run(&sc, &opts, &mut |_| {}).expect("warm-up run");
    ThermalReport::of(&sc, &r.trace)
        .expect("thermal report")
        .markdown()
}

fn rate_source() -> String {
    use paragyro_simulator::rate_response::{Options, chirp, ramp, step};
    let o = Options {
        precision: paragyro_simulator::runner::Precision::F32,
        seed: 1,
        allan_s: None,
        allan_zero_memory_s: None,
        allan_forgetting: None,
        allan_settle_s: 0.0,
        allan_warm_start: false,
    };
    let f = chirp(&o, 0.1, 200.0, 20.0, 24.0).expect("chirp");
    let (st, _) = step(&o).expect("step");
    let (r, _) = ramp(&o).expect("ramp");
    format!(
        "bandwidth {:.1} Hz, step {:.2} %, scale factor {:.0} ppm, nonlinearity {:.0} ppm FS",
        f.bandwidth_3db_hz.unwrap_or(f64::NAN),
        st.max_err_after_25ms_pct,
        r.scale_factor_err_ppm,
        r.nonlinearity_ppm_fs
    )
}

/// The results section of blind run 31 (the independent generator's records, pooled with
/// run 30) in its results file.
fn blind_source() -> String {
    let text = read("host-sim/diagnose/blind-benchmark.md");
    let start = text
        .find("## Run 31 results")
        .expect("blind-benchmark.md has \"## Run 31 results\"");
    let rest = &text[start..];
    let end = rest[3..].find("\n## ").map_or(rest.len(), |k| k + 3);
    rest[..end].to_string()
}

#[test]
fn the_headline_table_is_what_its_sources_give() {
    let readme = read("README.md");
    let rows = headline_rows(&readme);
    assert!(rows.len() >= 5, "only {} headline rows", rows.len());
    let (budget, measured) = budget_source();
    let blind = blind_source();
    // the rate channel runs beside the results table (seconds each)
    let mut rate_run = rows
        .iter()
        .any(|r| r.2.contains("paragyro-sim -- rate-response"))
        .then(|| std::thread::spawn(rate_source));
    let mut rate: Option<String> = None;
    let mut thermal: Option<String> = None;
    let mut bad = Vec::new();
    for (figure, value, source) in &rows {
        let (src, partial) = if source.contains("paragyro-sim -- results") {
            (results(), false)
        } else if source.contains("paragyro-sim -- rate-response") {
            if rate.is_none() {
                rate = rate_run.take().map(|h| h.join().expect("rate-response"));
            }
            (rate.as_deref().unwrap_or(""), false)
        } else if source.contains("paragyro-sim -- thermal") {
            (thermal.get_or_insert_with(thermal_source).as_str(), false)
        } else if source.contains("paragyro-fil -- budget") {
            (budget.as_str(), !measured)
        } else if source.contains("paragyro-refsim --example score -- out/refsim-3333") {
            (blind.as_str(), false)
        } else {
            bad.push(format!("{figure}: no known source in `{source}`"));
            continue;
        };
        let miss = missing(value, src);
        // without the firmware's artifacts only the budgets can be checked
        if !miss.is_empty() && !partial {
            bad.push(format!(
                "{figure}: {value}: the source does not give {miss:?}; it gives:\n{src}"
            ));
        }
    }
    // the same four figures in the host-sim guide's datasheet
    let rate = rate.unwrap_or_else(rate_source);
    let guide = read("host-sim/README.md");
    for quantity in [
        "| bandwidth",
        "| 100 °/s step",
        "| scale-factor error",
        "| nonlinearity",
    ] {
        let row = guide
            .lines()
            .find(|l| l.starts_with(quantity))
            .unwrap_or_else(|| panic!("host-sim/README.md datasheet has no row {quantity}"));
        let value = row.split(" | ").nth(1).unwrap_or("");
        let miss = missing(value, &rate);
        if !miss.is_empty() {
            bad.push(format!(
                "host-sim/README.md datasheet {row}: the source does not give {miss:?}; it gives {rate}"
            ));
        }
    }
    if !measured {
        eprintln!(
            "headline: the firmware's measured figures not checked (PARAGYRO_FW_FIGURES=1 after bash .ci/run)"
        );
    }
    assert!(
        bad.is_empty(),
        "README.md headline table:\n{}",
        bad.join("\n")
    );
}

/// host-sim/README.md's results table is what `paragyro-sim results` prints (but the wall
/// times): regenerate it with that command when the estimator or the simulator changes.
#[test]
fn the_results_table_of_the_host_sim_guide_is_what_results_gives() {
    let guide = read("host-sim/README.md");
    let start = guide
        .find("## Results")
        .expect("host-sim/README.md has ## Results");
    let section = &guide[start..];
    let end = section[3..].find("\n## ").map_or(section.len(), |k| k + 3);
    let documented = result_rows(&section[..end]);
    let measured = result_rows(results());
    assert!(!measured.is_empty(), "no rows from results_table");
    assert_eq!(
        documented, measured,
        "host-sim/README.md \"Results\" differs from `cargo run --release -p paragyro-sim -- results`"
    );
}

/// The rows whose source is `paragyro-fil -- budget` alone: with `PARAGYRO_FW_FIGURES=1`
/// their measured flash, RAM and tick against the artifacts `bash .ci/run` leaves (the test
/// above checks every other row, and these against the budgets); `.ci/run` runs this one
/// after it measures them, without regenerating the simulated rows' sources.
#[test]
fn the_headline_firmware_rows_are_the_measured_figures() {
    let readme = read("README.md");
    let (budget, measured) = budget_source();
    let rows: Vec<_> = headline_rows(&readme)
        .into_iter()
        .filter(|r| r.2.contains("paragyro-fil -- budget"))
        .collect();
    assert!(
        !rows.is_empty(),
        "no headline row names `paragyro-fil -- budget`"
    );
    if !measured {
        eprintln!(
            "headline: the firmware's measured figures not checked (PARAGYRO_FW_FIGURES=1 after bash .ci/run)"
        );
        return;
    }
    let bad: Vec<String> = rows
        .iter()
        .filter_map(|(figure, value, _)| {
            let miss = missing(value, &budget);
            (!miss.is_empty()).then(|| {
                format!("{figure}: {value}: the source does not give {miss:?}; it gives:\n{budget}")
            })
        })
        .collect();
    assert!(
        bad.is_empty(),
        "README.md headline table:\n{}",
        bad.join("\n")
    );
}

#[test]
fn budgets_in_the_headline_are_the_enforced_ones() {
    let readme = read("README.md");
    let (budget, _) = budget_source();
    let budget_numbers = numbers(&budget);
    for (figure, value, source) in headline_rows(&readme) {
        if source.contains("paragyro-fil -- budget") {
            // "of N" and "budget A / B" are the enforced budgets
            let stated: Vec<String> = value
                .split(" of ")
                .skip(1)
                .chain(value.split("budget ").skip(1))
                .flat_map(numbers)
                .collect();
            for n in stated {
                assert!(
                    budget_numbers.contains(&n),
                    "{figure}: budget {n} is not paragyro_fil::budget's ({budget})"
                );
            }
        }
    }
}

#[test]
fn numbers_are_read_as_written() {
    assert_eq!(
        numbers("65 416 B of 65 536 B; θ14 0.48 %, f32 (0.074 %)"),
        ["65 416", "65 536", "0.48", "0.074"]
    );
    assert_eq!(
        numbers("11 712 mean, 14 654 max (budget 12 000 / 15 000)."),
        ["11 712", "14 654", "12 000", "15 000"]
    );
    assert_eq!(numbers("95 % / 90 % / 100 %"), ["95", "90", "100"]);
    assert_eq!(grouped(65536), "65 536");
    assert_eq!(grouped(999), "999");
    assert_eq!(
        missing("0.48 % and 0.21 %", "θ14 0.48 %, θ17 0.22 %"),
        ["0.21"]
    );
}
