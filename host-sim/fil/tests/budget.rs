//! `paragyro-fil budget`: what it says when its inputs are missing or wrong.
//!
//! The budgets themselves (flash, RAM with the stack peak, the tick) are checked on real
//! artifacts by `.ci/run`, which runs the binary this test builds
//! (`target/debug/paragyro-fil budget target/paragyro-firmware-stm32f405.elf`); the arithmetic
//! is `paragyro_fil::budget`'s unit tests.

use std::path::PathBuf;
use std::process::{Command, Output};

fn budget(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_paragyro-fil"))
        .arg("budget")
        .args(args)
        .output()
        .expect("paragyro-fil runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fil-budget");
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir.join(name)
}

#[test]
fn without_an_image_it_prints_its_usage_and_exits_2() {
    let o = budget(&[]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("usage: paragyro-fil budget STM32F405_ELF"));
}

#[test]
fn a_missing_image_is_named_with_the_command_that_builds_it() {
    let elf = scratch("no-such-image.elf");
    let o = budget(&[elf.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("no-such-image.elf"), "{e}");
    assert!(e.contains("cargo fw-stm32"), "{e}");
}

#[test]
fn a_missing_or_malformed_summary_is_named() {
    let elf = scratch("image.elf");
    std::fs::write(&elf, b"\x7fELF").expect("write");
    let missing = scratch("no-such-summary.json");
    let o = budget(&[elf.to_str().unwrap(), missing.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("no-such-summary.json") && e.contains("cargo fw-loop"),
        "{e}"
    );

    let bad = scratch("bad-summary.json");
    std::fs::write(&bad, "{\"instr_mean\": 1}").expect("write");
    let o = budget(&[elf.to_str().unwrap(), bad.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("bad-summary.json"), "{}", stderr(&o));
}
