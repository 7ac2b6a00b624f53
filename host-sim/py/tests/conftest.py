"""Fixtures of the Python package's tests: the CLI they compare with and small simulated
records (8 s: what the checks need, not the 10–60 s of the benchmarks)."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

import paragyro

ROOT = Path(__file__).resolve().parents[3]
#: Length of the simulated records of the tests, s.
DURATION_S = 8.0


def _sim_bin() -> Path:
    """The `paragyro-sim` binary: PARAGYRO_SIM_BIN (cargo xtask sets it: the one `cargo test
    --workspace` builds, in the test profile), else built in release."""
    env = os.environ.get("PARAGYRO_SIM_BIN")
    if env:
        return Path(env)
    target = Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target"))
    subprocess.run(
        ["cargo", "build", "-q", "--release", "-p", "paragyro-sim"],
        cwd=ROOT,
        check=True,
    )
    return target / "release" / "paragyro-sim"


@pytest.fixture(scope="session")
def sim_bin() -> Path:
    p = _sim_bin()
    assert p.exists(), f"no paragyro-sim at {p}"
    return p


@pytest.fixture(scope="session")
def cli(sim_bin):
    """Runs `paragyro-sim ARGS`; returns the CompletedProcess (text)."""

    def run(*args: str, check: bool = True) -> subprocess.CompletedProcess:
        r = subprocess.run([str(sim_bin), *map(str, args)], capture_output=True, text=True)
        if check and r.returncode != 0:
            raise AssertionError(f"paragyro-sim {' '.join(map(str, args))}: exit {r.returncode}\n{r.stderr}")
        return r

    return run


@pytest.fixture(scope="session")
def rec_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("records")


@pytest.fixture(scope="session")
def identify_csv(rec_dir) -> Path:
    """A clean 8 s `identify` record with its truth beside it (seed 3)."""
    out = rec_dir / "identify-3.csv"
    paragyro.simulate("identify", seed=3, duration_s=DURATION_S, out=out)
    return out


def cli_report(cli, csv: Path, out: Path, *flags: str) -> dict:
    """The CLI's report.json of `paragyro-sim diagnose CSV --out OUT FLAGS`."""
    cli("diagnose", csv, "--out", out, *flags)
    return json.loads((out / "report.json").read_text())


def without_timing(report: dict) -> dict:
    """report.json less its wall times (`seconds`, `timing_s`), which differ run to run."""
    r = dict(report)
    r.pop("seconds")
    r.pop("timing_s")
    return r
