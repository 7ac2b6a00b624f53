//! The Python package's tests (`host-sim/py`), run by `cargo xtask test` after
//! `cargo test --workspace` (or alone: `cargo xtask py [PYTEST ARGS]`):
//!
//! 1. a virtual environment `target/py-venv` made with `python3 -m venv` (`PARAGYRO_PYTHON`
//!    names another interpreter; Python ≥ 3.9), kept between runs;
//! 2. `pip install -r host-sim/py/requirements-test.txt` (pinned maturin, numpy, pandas,
//!    pyarrow, polars, dask, distributed, pytest), skipped when the venv already has that
//!    exact file's packages (a stamp holds its text);
//! 3. the package built and installed into it: `maturin develop` in the dev profile at the
//!    test profile's opt-level (`CARGO_PROFILE_DEV_OPT_LEVEL=3`; the test profile is the dev
//!    one at opt-level 3), so that it reuses what `cargo test --workspace` compiled and builds
//!    only pyo3 and the bindings (`--profile test` itself cannot be used: maturin builds with
//!    `cargo rustc`, for which it means a test harness);
//! 4. the CLI the tests compare against: the `paragyro-sim` binary `cargo test --workspace`
//!    builds (in the test profile, for `host-sim/cli/tests/binary.rs`; `cargo test
//!    --workspace --no-run`, at once after `cargo xtask test`'s test run, which just built
//!    it), handed over as `PARAGYRO_SIM_BIN`;
//! 5. `pytest host-sim/py/tests`.
//!
//! `--no-python` or `PARAGYRO_SKIP_PYTHON=1` skips all of it.

use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use crate::{cargo, say};

/// The cargo profile of the extension, and the opt-level that makes it the test profile's.
const PROFILE: &str = "dev";
const PROFILE_OPT_LEVEL: (&str, &str) = ("CARGO_PROFILE_DEV_OPT_LEVEL", "3");

/// The output directory of the test profile, where `cargo test` builds the CLI.
const TEST_PROFILE_DIR: &str = "debug";

/// The workspace root (this crate is `tests/xtask`).
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

fn target_dir(root: &Path) -> PathBuf {
    env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target"))
}

/// The venv with the pinned packages (steps 1 and 2), nothing built: `cargo xtask prepare`.
pub fn prepare() -> Result<(), String> {
    let root = root();
    venv_with_packages(&root, &target_dir(&root).join("py-venv")).map(|_| ())
}

/// The venv's interpreter, the venv made and its packages installed where needed.
fn venv_with_packages(root: &Path, venv: &Path) -> Result<PathBuf, String> {
    let t = Instant::now();
    let py = venv_python(venv)?;
    install_requirements(root, venv, &py)?;
    took("venv and packages", t);
    Ok(py)
}

/// Builds the package into the venv and runs its pytest suite (`pytest_args` passed on);
/// says how long each step took.
pub fn test(pytest_args: &[String]) -> Result<(), String> {
    let root = root();
    let target = target_dir(&root);
    let venv = target.join("py-venv");
    let py = venv_with_packages(&root, &venv)?;
    let bin_dir = venv.join("bin");
    let path = match env::var_os("PATH") {
        Some(p) => {
            let mut dirs = vec![bin_dir.clone()];
            dirs.extend(env::split_paths(&p));
            env::join_paths(dirs).map_err(|e| format!("PATH: {e}"))?
        }
        None => bin_dir.clone().into_os_string(),
    };
    let venv_env = [
        ("VIRTUAL_ENV", venv.clone().into_os_string()),
        ("PATH", path),
    ];
    let manifest = root.join("host-sim/py/Cargo.toml");
    say(&format!(
        "maturin develop --profile {PROFILE} ({}={}: the test profile's; the package into {})",
        PROFILE_OPT_LEVEL.0,
        PROFILE_OPT_LEVEL.1,
        venv.display()
    ));
    let t = Instant::now();
    run(
        Command::new(bin_dir.join("maturin"))
            .args(["develop", "--quiet", "--profile", PROFILE])
            .arg("--manifest-path")
            .arg(&manifest)
            .env(PROFILE_OPT_LEVEL.0, PROFILE_OPT_LEVEL.1)
            .envs(venv_env.iter().cloned()),
        "maturin develop",
    )?;
    took("the package", t);
    say("cargo test --workspace --no-run (the CLI the tests compare with, as the tests build it)");
    let t = Instant::now();
    run(
        Command::new(cargo())
            .args(["test", "-q", "--workspace", "--no-run"])
            .current_dir(&root),
        "cargo test --workspace --no-run",
    )?;
    took("the CLI", t);
    let sim = target.join(TEST_PROFILE_DIR).join("paragyro-sim");
    say("pytest host-sim/py/tests");
    let t = Instant::now();
    run(
        Command::new(&py)
            .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
            .arg(root.join("host-sim/py/tests"))
            .args(pytest_args)
            .env("PARAGYRO_SIM_BIN", &sim)
            .envs(venv_env.iter().cloned())
            .current_dir(&root),
        "pytest host-sim/py/tests",
    )?;
    took("pytest", t);
    Ok(())
}

fn took(what: &str, t: Instant) {
    say(&format!("  {what}: {:.0} s", t.elapsed().as_secs_f64()));
}

/// The venv's interpreter, making the venv first if needed.
fn venv_python(venv: &Path) -> Result<PathBuf, String> {
    let py = venv.join("bin/python");
    if py.exists() {
        return Ok(py);
    }
    let base = env::var("PARAGYRO_PYTHON").unwrap_or_else(|_| "python3".into());
    let check = Command::new(&base)
        .args([
            "-c",
            "import sys, venv; sys.exit(0 if sys.version_info >= (3, 9) else 1)",
        ])
        .status()
        .map_err(|e| {
            format!(
                "cannot run `{base}` ({e}): the Python tests need Python ≥ 3.9 with venv \
                 (Debian: `apt-get install python3 python3-venv`; PARAGYRO_PYTHON names \
                 another interpreter), or skip them with --no-python / PARAGYRO_SKIP_PYTHON=1"
            )
        })?;
    if !check.success() {
        return Err(format!(
            "`{base}` is not Python ≥ 3.9 with the venv module: set PARAGYRO_PYTHON to one, \
             or skip the Python tests with --no-python / PARAGYRO_SKIP_PYTHON=1"
        ));
    }
    say(&format!("{base} -m venv {}", venv.display()));
    run(
        Command::new(&base).args(["-m", "venv"]).arg(venv),
        "python3 -m venv",
    )
    .map_err(|e| {
        format!(
            "{e}: the venv could not be made (Debian: `apt-get install python3-venv`), or \
             skip the Python tests with --no-python / PARAGYRO_SKIP_PYTHON=1"
        )
    })?;
    Ok(py)
}

/// `pip install -r requirements-test.txt`, unless the venv's stamp says it is done.
fn install_requirements(root: &Path, venv: &Path, py: &Path) -> Result<(), String> {
    let req = root.join("host-sim/py/requirements-test.txt");
    let want = std::fs::read_to_string(&req).map_err(|e| format!("{}: {e}", req.display()))?;
    let stamp = venv.join("paragyro-requirements.txt");
    if std::fs::read_to_string(&stamp).is_ok_and(|s| s == want) {
        say("python packages: installed (host-sim/py/requirements-test.txt)");
        return Ok(());
    }
    say("pip install -r host-sim/py/requirements-test.txt");
    let status = Command::new(py)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
        ])
        .args(["--timeout", "60", "--retries", "2", "-r"])
        .arg(&req)
        .status()
        .map_err(|e| format!("cannot run pip: {e}"))?;
    if !status.success() {
        return Err(format!(
            "pip could not install host-sim/py/requirements-test.txt ({status}): is the \
             package index (PyPI) reachable from here? pip's own message is above; behind a \
             proxy or a mirror set PIP_INDEX_URL / HTTPS_PROXY, or skip the Python tests with \
             --no-python / PARAGYRO_SKIP_PYTHON=1"
        ));
    }
    std::fs::write(&stamp, want).map_err(|e| format!("{}: {e}", stamp.display()))
}

fn run(cmd: &mut Command, what: &str) -> Result<(), String> {
    let status = cmd
        .status()
        .map_err(|e| format!("cannot start {what}: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what} failed: {status}"))
    }
}
