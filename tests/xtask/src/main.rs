//! `cargo xtask test [ARGS]`: the README's test command.
//!
//! `cargo test --workspace` alone needs three things a fresh machine does not have: the
//! `thumbv7em-none-eabihf` target (the firmware-in-QEMU test builds the firmware),
//! `qemu-system-arm` (it runs it) and `defmt-print` (it decodes its output). This installs
//! each one that is missing, says what it did, and then runs `cargo test --workspace` with
//! any further arguments passed through. It never updates the toolchain (no
//! `rustup update`, no `rust-toolchain.toml`): it only adds the target.
//!
//! * `cargo xtask test` — install what is missing, then run every test.
//! * `cargo xtask test --no-install` — run the tests as the machine is (the QEMU test then
//!   fails with a message naming what is missing, or is skipped with `PARAGYRO_SKIP_QEMU=1`).
//! * `cargo xtask setup` — only install.
//! * `cargo xtask prepare` — only the installs that mostly wait on the network: the thumb
//!   target, `qemu-system-arm`, `cc`/`c++`, and the Python tests' venv with its packages
//!   (module [`python`]). `.ci/run` runs it beside the lints (the built binary, so that it
//!   takes no cargo lock); `cargo xtask test` then finds them and installs only
//!   `defmt-print`, whose build needs the CPU the lints use.
//! * `cargo xtask fuzz [--secs N] [TARGET ...]` — the bounded libFuzzer run of `tests/fuzz`
//!   (module [`fuzz`]); `cargo xtask test` builds its targets in the background while the
//!   tests run and runs them after the tests, 20 s per target (`PARAGYRO_FUZZ_SECS` sets
//!   another length, `PARAGYRO_SKIP_FUZZ=1` skips it; `PARAGYRO_FUZZ_DEFER=1` builds them
//!   but leaves their run to a later `cargo xtask fuzz`: `.ci/run` runs it beside the
//!   firmware step, whose QEMU runs and LTO links keep one core busy, not two).
//! * `cargo xtask py [PYTEST ARGS]` — the Python package's tests alone (module [`python`]):
//!   a venv `target/py-venv` with the pinned packages of `host-sim/py/requirements-test.txt`,
//!   the package built into it with maturin, then pytest. `cargo xtask test` runs them after
//!   `cargo test --workspace`; `--no-python` or `PARAGYRO_SKIP_PYTHON=1` skips them.
//!
//! `qemu-system-arm` comes from Debian's packages (`apt-get`, as root: CI and these
//! machines run as root); elsewhere the message says what to install by hand. The
//! firmware-in-the-loop test (tests/tests/fil.rs) needs QEMU too, and a C compiler (`cc`)
//! for its instruction-count plugin: Rust's host linking needs `cc` anyway, so it is only
//! checked (and installed with `gcc` from Debian's packages if missing, as root). libFuzzer
//! is C++: `c++` is checked the same way (Debian's `g++`).
#![forbid(unsafe_code)]

mod fuzz;
mod python;

use std::env;
use std::process::{Command, ExitCode, Stdio};

const THUMB: &str = "thumbv7em-none-eabihf";
const DEFMT_PRINT: &str = "defmt-print@1.2.0";

fn main() -> ExitCode {
    let mut args: Vec<String> = env::args().skip(1).collect();
    if args.is_empty() {
        eprintln!("{}", usage());
        return ExitCode::from(2);
    }
    let task = args.remove(0);
    let result = match task.as_str() {
        "setup" => setup(),
        "prepare" => prepare(),
        "fuzz" => fuzz::fuzz(&args),
        "py" => python::test(&args),
        "test" => {
            let install = !take_flag(&mut args, "--no-install");
            let python = !take_flag(&mut args, "--no-python")
                && env::var_os("PARAGYRO_SKIP_PYTHON").is_none_or(|v| v.is_empty() || v == "0");
            (if install { setup() } else { Ok(()) }).and_then(|()| test(&args, python))
        }
        "-h" | "--help" | "help" => {
            println!("{}", usage());
            Ok(())
        }
        other => Err(format!("unknown task `{other}`\n{}", usage())),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

fn usage() -> &'static str {
    "usage: cargo xtask <task>\n\
     \x20 test [--no-install] [CARGO TEST ARGS]   install what the tests need, then `cargo test --workspace`\n\
     \x20                                         and the bounded libFuzzer run (tests/fuzz)\n\
     \x20 fuzz [--secs N] [TARGET ...]            the libFuzzer run alone (N s per target, default 20)\n\
     \x20 setup                                   only install (thumb target, qemu-system-arm, defmt-print, cc, c++)\n\
     \x20 prepare                                 only the network-bound installs (thumb target, qemu-system-arm,\n\
     \x20                                         cc, c++, the Python tests' venv and packages)"
}

fn take_flag(args: &mut Vec<String>, flag: &str) -> bool {
    let before = args.len();
    args.retain(|a| a != flag);
    args.len() != before
}

/// Installs the thumb target, `qemu-system-arm`, `cc`, `c++` and `defmt-print` where
/// missing.
fn setup() -> Result<(), String> {
    system()?;
    defmt_print()
}

/// What [`setup`] installs but `defmt-print` (a build: CPU, not network), and the Python
/// tests' venv with its packages.
fn prepare() -> Result<(), String> {
    let t0 = std::time::Instant::now();
    system()?;
    python::prepare()?;
    say(&format!("prepared in {:.0} s", t0.elapsed().as_secs_f64()));
    Ok(())
}

/// The thumb target, `qemu-system-arm`, `cc` and `c++`, each installed where missing.
fn system() -> Result<(), String> {
    let installed = output("rustup", &["target", "list", "--installed"])
        .map_err(|e| format!("cannot run rustup ({e}): the thumb target must be added by hand"))?;
    if installed.lines().any(|l| l.trim() == THUMB) {
        say(&format!("{THUMB}: installed"));
    } else {
        say(&format!("{THUMB}: adding it (rustup target add {THUMB})"));
        run("rustup", &["target", "add", THUMB])?;
    }

    if found("qemu-system-arm") {
        say("qemu-system-arm: installed");
    } else if is_root() && found("apt-get") {
        say("qemu-system-arm: installing it (apt-get install qemu-system-arm)");
        run("apt-get", &["update", "-qq"])?;
        run_env(
            "apt-get",
            &[
                "install",
                "-y",
                "-qq",
                "--no-install-recommends",
                "qemu-system-arm",
            ],
            &[("DEBIAN_FRONTEND", "noninteractive")],
        )?;
    } else {
        return Err(
            "qemu-system-arm is missing and cannot be installed from here (not root, \
                    or no apt-get): install it (Debian/Ubuntu: `apt-get install \
                    qemu-system-arm`), or run `cargo xtask test --no-install` with \
                    PARAGYRO_SKIP_QEMU=1 to skip the firmware-in-QEMU test"
                .into(),
        );
    }

    compiler(
        "cc",
        "gcc",
        "a C compiler",
        "QEMU plugin of the firmware-in-the-loop test",
    )?;
    compiler(
        "c++",
        "g++",
        "a C++ compiler",
        "libFuzzer, `cargo xtask fuzz`",
    )
}

/// `defmt-print`, built with `cargo install` where missing.
fn defmt_print() -> Result<(), String> {
    if found("defmt-print") {
        say("defmt-print: installed");
    } else {
        // unoptimised: it decodes the QEMU runs' few thousand lines either way, and its
        // build takes 53 s where the release profile's takes 84 s (this 2-core machine,
        // `cargo install [--debug] --locked defmt-print@1.2.0`, sources already fetched)
        say(&format!(
            "defmt-print: installing it (cargo install --debug --locked {DEFMT_PRINT})"
        ));
        run(
            "cargo",
            &["install", "--debug", "--locked", "--quiet", DEFMT_PRINT],
        )?;
    }
    Ok(())
}

/// `cargo test --workspace ARGS`, then (on a full run) the Python tests and the fuzzing.
///
/// On a full run the fuzz targets build in the background at the lowest CPU priority while
/// the tests run (built first, `--no-run`): the tests leave a core idle for much of their
/// run, and the build takes it.
fn test(args: &[String], python: bool) -> Result<(), String> {
    let full = args.is_empty();
    let mut all = vec!["test".to_string(), "--workspace".to_string()];
    all.extend(args.iter().cloned());
    let refs: Vec<&str> = all.iter().map(String::as_str).collect();
    // the libFuzzer run of the fuzz targets (tests/fuzz is its own workspace; bounded,
    // stable, no sanitizer); only on a full run, PARAGYRO_SKIP_FUZZ=1 skips it
    let fuzzing = if full && env::var_os("PARAGYRO_SKIP_FUZZ").is_none() {
        let secs =
            match env::var("PARAGYRO_FUZZ_SECS") {
                Ok(v) => v.parse().ok().filter(|s| *s > 0).ok_or_else(|| {
                    format!("PARAGYRO_FUZZ_SECS={v}: not a positive whole number")
                })?,
                Err(_) => fuzz::DEFAULT_SECS,
            };
        say("cargo test --workspace --no-run");
        run(&cargo(), &["test", "--workspace", "--no-run"])?;
        Some((secs, fuzz::Build::start(true)?))
    } else {
        None
    };
    say(&format!("cargo {}", refs.join(" ")));
    let tests = run(&cargo(), &refs).and_then(|()| {
        // the Python package (host-sim/py): only on a full run, like the fuzzing
        if full {
            if python {
                let t0 = std::time::Instant::now();
                python::test(&[])?;
                say(&format!(
                    "python tests: {:.0} s (venv, packages, build, pytest)",
                    t0.elapsed().as_secs_f64()
                ));
            } else {
                say("python tests: skipped (--no-python or PARAGYRO_SKIP_PYTHON)");
            }
        }
        Ok(())
    });
    match (tests, fuzzing) {
        (Err(e), fuzzing) => {
            if let Some((_, build)) = fuzzing {
                build.stop();
            }
            Err(e)
        }
        (Ok(()), Some((secs, build))) => {
            let t0 = std::time::Instant::now();
            build.finish()?;
            say(&format!(
                "fuzz targets built (waited {:.0} s for the background build)",
                t0.elapsed().as_secs_f64()
            ));
            if env::var_os("PARAGYRO_FUZZ_DEFER").is_some_and(|v| !v.is_empty() && v != "0") {
                say(
                    "fuzz run deferred (PARAGYRO_FUZZ_DEFER): `cargo xtask fuzz` runs the built targets",
                );
                return Ok(());
            }
            fuzz::run_built(&fuzz::TARGETS, secs)
        }
        (Ok(()), None) => Ok(()),
    }
}

fn cargo() -> String {
    env::var("CARGO").unwrap_or_else(|_| "cargo".into())
}

fn say(s: &str) {
    println!("xtask: {s}");
}

/// `cmd` found, or installed from Debian's `package` (as root), or an error naming it.
fn compiler(cmd: &str, package: &str, what: &str, purpose: &str) -> Result<(), String> {
    if found(cmd) {
        say(&format!("{cmd}: installed ({purpose})"));
        return Ok(());
    }
    if !(is_root() && found("apt-get")) {
        return Err(format!(
            "{what} (`{cmd}`, for the {purpose}) is missing: install {package}"
        ));
    }
    say(&format!("{cmd}: installing it (apt-get install {package})"));
    run("apt-get", &["update", "-qq"])?;
    run_env(
        "apt-get",
        &["install", "-y", "-qq", "--no-install-recommends", package],
        &[("DEBIAN_FRONTEND", "noninteractive")],
    )
}

fn found(cmd: &str) -> bool {
    Command::new(cmd)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
}

fn is_root() -> bool {
    output("id", &["-u"]).is_ok_and(|s| s.trim() == "0")
}

fn output(cmd: &str, args: &[&str]) -> Result<String, String> {
    let out = Command::new(cmd)
        .args(args)
        .output()
        .map_err(|e| format!("{cmd}: {e}"))?;
    if !out.status.success() {
        return Err(format!("`{cmd} {}` failed: {}", args.join(" "), out.status));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn run(cmd: &str, args: &[&str]) -> Result<(), String> {
    run_env(cmd, args, &[])
}

fn run_env(cmd: &str, args: &[&str], envs: &[(&str, &str)]) -> Result<(), String> {
    let status = Command::new(cmd)
        .args(args)
        .envs(envs.iter().copied())
        .status()
        .map_err(|e| format!("cannot start `{cmd}`: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{cmd} {}` failed: {status}", args.join(" ")))
    }
}
