"""The rate-response datasheet: the CLI's library function (`rate_response::run_all`, which
`paragyro-sim rate-response` calls), so the front page's figures (README.md, "Headline
figures": 79.5 Hz / 0.49 % / −3 ppm / 47 ppm FS for the f32 core, seed 1)."""

from __future__ import annotations

import json

import pytest

import paragyro


def test_datasheet_is_the_headlines_and_its_report_json(tmp_path):
    r = paragyro.rate_response(seed=1, out=tmp_path / "rate")
    assert r["precision"] == "f32" and r["seed"] == 1
    assert round(r["frequency"]["bandwidth_3db_hz"], 1) == 79.5
    assert round(r["step"]["max_err_after_25ms_pct"], 2) == 0.49
    assert round(r["ramp"]["scale_factor_err_ppm"]) == -3
    assert round(r["ramp"]["nonlinearity_ppm_fs"]) == 47
    assert r["allan"] == []
    md = r.pop("markdown")
    assert "79.5" in md
    # what it wrote is what it returned, and the report's files are the CLI's
    written = json.loads((tmp_path / "rate" / "report.json").read_text())
    assert written == r
    assert (tmp_path / "rate" / "report.md").exists()
    assert any(p.suffix == ".png" for p in (tmp_path / "rate").iterdir())


def test_an_allan_settle_that_is_not_a_time_is_an_argument_error():
    # refused before any run: the static runs would take minutes
    with pytest.raises(paragyro.ArgumentError):
        paragyro.rate_response(allan_s=10.0, allan_settle_s=-1.0)
    with pytest.raises(paragyro.ArgumentError):
        paragyro.rate_response(allan_s=10.0, allan_settle_s=float("nan"))


def test_a_forgetting_outside_0_1_is_an_argument_error():
    for bad in (0.0, 1.5, float("nan")):
        with pytest.raises(paragyro.ArgumentError):
            paragyro.rate_response(allan_s=10.0, allan_forgetting=bad)
