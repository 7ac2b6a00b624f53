"""simulate → diagnose, typed; the same report.json as the CLI; run_core = `replay`."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import paragyro
from conftest import DURATION_S, cli_report, without_timing


@pytest.fixture(scope="module")
def damped_csv(rec_dir):
    """8 s of `identify` with nonlinear damping, seed 5."""
    out = rec_dir / "damped-5.csv"
    paragyro.simulate("identify", seed=5, duration_s=DURATION_S, effects={"nonlinear_damping": 2e-5}, out=out)
    return out


@pytest.fixture(scope="module")
def damped(damped_csv):
    return paragyro.diagnose(damped_csv)


def test_diagnosis_is_typed(damped):
    d = damped
    assert isinstance(d, paragyro.Diagnosis)
    assert d.verdict in {"none", "unknown"} | {n for n, _, lib in paragyro.effects() if lib}
    assert d.ranking and all(isinstance(c, paragyro.Candidate) for c in d.ranking)
    top = d.top
    assert top is not None and isinstance(top.gap_closure, float) and isinstance(top.significant, bool)
    wy2 = d.parameter_face.parameter("wy2")
    assert isinstance(wy2, paragyro.Parameter) and wy2.sigma > 0 and np.isfinite(wy2.t)
    assert d.noise_energy_ratio > 0 and d.residual_over_noise > 0
    assert d.output_error is not None and isinstance(d.output_error.before.combined, float)
    assert d.samples == int(DURATION_S * 500) + 1
    assert d.seconds > 0 and "rows" in d.timing_s and "resimulate_model" in d.timing_s


def test_the_added_effect_is_found(damped):
    # 2e-5 nonlinear damping on 8 s: the verdict names it, its size within 2 %
    assert damped.verdict == "nonlinear_damping", damped.to_dict()["ranking"][:2]
    c = damped.top
    assert c.effect == "nonlinear_damping" and c.significant
    assert abs(c.size - 2e-5) < 0.02 * 2e-5, c.size
    assert c.size_sigma is not None and 0 < c.size_sigma < 0.1 * c.size


def test_report_is_the_clis(damped, damped_csv, cli, tmp_path):
    ours = damped.to_dict()
    theirs = cli_report(cli, damped_csv, tmp_path / "cli")
    assert without_timing(ours) == without_timing(theirs)
    # to_dict parses the same serde JSON: its keys, its types
    assert json.loads(damped.to_json()) == ours
    files = damped.write_report(tmp_path / "py")
    names = sorted(p.rsplit("/", 1)[-1] for p in files)
    assert names == sorted(p.name for p in (tmp_path / "cli").iterdir())
    md_ours = (tmp_path / "py" / "report.md").read_text()
    assert md_ours.splitlines()[0] == (tmp_path / "cli" / "report.md").read_text().splitlines()[0]


def test_record_object_and_no_resim(identify_csv, cli, tmp_path):
    rec = paragyro.read_record(identify_csv)
    d = paragyro.diagnose(rec, resimulate=False)
    assert d.output_error is None and d.verdict == "none"
    theirs = cli_report(cli, identify_csv, tmp_path / "cli", "--no-resim")
    assert without_timing(d.to_dict()) == without_timing(theirs)


def test_run_core_is_the_clis_replay(identify_csv, cli, tmp_path):
    df = paragyro.run_core(identify_csv)
    cli("replay", identify_csv, "--out", tmp_path / "replay")
    theirs = pd.read_csv(tmp_path / "replay" / "estimates.csv")
    assert list(df.columns) == list(theirs.columns)
    assert len(df) == len(theirs)
    for k in df.columns:
        assert np.array_equal(df[k].to_numpy(), theirs[k].to_numpy(), equal_nan=True), k
    assert df["health"].dtype == np.int64
    # the identified rate: the identify scenario's 150 °/s
    assert abs(df["rate_dps_est"].iloc[-1] - 150.0) < 1.5
    f64 = paragyro.run_core(paragyro.read_record(identify_csv), precision="f64")
    assert not np.array_equal(f64["th14_est"].to_numpy(), df["th14_est"].to_numpy())
    with pytest.raises(paragyro.ArgumentError):
        paragyro.run_core(identify_csv, precision="f16")
