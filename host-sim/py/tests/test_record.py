"""Records: the round trip is exact, pandas in and out, errors with the CLI's file, line
and column."""

from __future__ import annotations

import numpy as np
import pytest

import paragyro
from conftest import DURATION_S


def test_simulated_record_has_the_format_and_its_truth(identify_csv):
    rec = paragyro.read_record(identify_csv)
    assert rec.header["format"] == "paragyro-record 1"
    assert rec.header["fs_hz"] == 500.0 and rec.header["lockin_lpf_order"] == 4
    assert rec.header["device"] == "simulated"
    assert list(rec.columns)[:19] == list(paragyro.REQUIRED_COLUMNS)
    assert len(rec) == int(DURATION_S * 500) + 1  # both ends
    assert np.all(np.diff(rec.columns["t_s"]) > 0)
    assert rec.warnings == []
    # the same simulation in memory: the same rows, bit for bit, and its truth
    mem = paragyro.simulate("identify", seed=3, duration_s=DURATION_S)
    assert mem.truth["seed"] == 3 and mem.truth["scenario"] == "identify"
    for k, v in rec.columns.items():
        assert np.array_equal(v.view(np.uint64), mem.columns[k].view(np.uint64)), k


def test_round_trip_is_exact(identify_csv, tmp_path):
    rec = paragyro.read_record(identify_csv)
    out = tmp_path / "copy.csv"
    paragyro.write_record(rec, out)
    assert out.read_bytes() == identify_csv.read_bytes()
    back = paragyro.read_record(out)
    assert back.header == rec.header
    for k in rec.columns:
        assert np.array_equal(back.columns[k].view(np.uint64), rec.columns[k].view(np.uint64))
    # through pandas: the header rides in df.attrs
    df = rec.to_pandas()
    assert list(df.columns) == list(rec.columns) and len(df) == len(rec)
    out2 = tmp_path / "from-pandas.csv"
    paragyro.write_record(df, out2)
    assert out2.read_bytes() == identify_csv.read_bytes()


def test_optional_columns_and_nan_rows(tmp_path):
    rec = paragyro.simulate("identify", seed=4, duration_s=2.0, temperature=(25.0, 4.0), rate_table=True)
    assert "temp_c" in rec.columns and "rate_ref_dps" in rec.columns
    assert rec.columns["temp_c"][0] == 25.0 and abs(rec.columns["temp_c"][-1] - 29.0) < 0.011
    rec.columns["rate_ref_dps"][10] = np.nan  # unknown: an empty field
    rec.columns["x1_re_um"][20] = np.nan  # kept, counted by the reader
    out = tmp_path / "opt.csv"
    paragyro.write_record(rec, out)
    lines = out.read_text().splitlines()
    header_row = next(i for i, l in enumerate(lines) if l.startswith("t_s,"))
    assert lines[header_row + 11].endswith(",")  # the empty rate_ref_dps field
    back = paragyro.read_record(out)
    assert np.isnan(back.columns["rate_ref_dps"][10]) and np.isnan(back.columns["x1_re_um"][20])
    assert len(back.warnings) == 1 and "NaN" in back.warnings[0]


def test_malformed_csv_raises_with_the_clis_file_line_column(identify_csv, tmp_path, cli):
    lines = identify_csv.read_text().splitlines(keepends=True)
    header_row = next(i for i, l in enumerate(lines) if l.startswith("t_s,"))
    row = lines[header_row + 5].split(",")
    row[6] = "abc"  # x1_re_um, field 7
    lines[header_row + 5] = ",".join(row)
    bad = tmp_path / "bad.csv"
    bad.write_text("".join(lines))
    with pytest.raises(paragyro.RecordError) as ei:
        paragyro.read_record(bad)
    e = ei.value
    assert isinstance(e, paragyro.ParagyroError)
    assert e.path == str(bad) and e.line == header_row + 6 and e.column == 7
    assert e.context == "column 'x1_re_um'" and e.kind == "number"
    assert str(e) == f"{bad}:{header_row + 6}:7: column 'x1_re_um': expected a number, found 'abc'"
    # the CLI says the same, and so do diagnose and run_core on the path
    r = cli("replay", bad, "--out", tmp_path / "replay", check=False)
    assert r.returncode == 2 and r.stderr.strip() == f"error: {e}"
    with pytest.raises(paragyro.RecordError) as e2:
        paragyro.diagnose(bad)
    assert (e2.value.line, e2.value.column) == (e.line, e.column)
    with pytest.raises(paragyro.RecordError):
        paragyro.run_core(str(bad))
    # the attributes survive pickling (a Dask worker's error)
    import pickle

    p = pickle.loads(pickle.dumps(e))
    assert (type(p), p.path, p.line, p.column, str(p)) == (type(e), e.path, e.line, e.column, str(e))


def test_writer_refuses_what_the_reader_refuses(identify_csv, tmp_path):
    rec = paragyro.read_record(identify_csv)
    rec.columns["t_s"][100] = rec.columns["t_s"][99]  # a repeated time stamp
    out = tmp_path / "never.csv"
    with pytest.raises(paragyro.RecordError) as ei:
        paragyro.write_record(rec, out)
    assert ei.value.kind == "time" and ei.value.context == "column 't_s'"
    assert not out.exists()
    del rec.columns["y3_im_um"]
    with pytest.raises(paragyro.ArgumentError, match="y3_im_um"):
        paragyro.write_record(rec, out)


def test_scenario_and_argument_errors(tmp_path, cli):
    toml = tmp_path / "x.toml"
    toml.write_text('name = "x"\nduration_s = "long"\n')
    with pytest.raises(paragyro.ScenarioError) as ei:
        paragyro.simulate(str(toml))
    e = ei.value
    assert e.path == str(toml) and e.line == 2 and e.column is not None
    r = cli("check", toml, check=False)
    assert r.returncode == 2 and r.stderr.strip() == f"error: {e}"
    with pytest.raises(paragyro.ScenarioError, match="no-such-scenario"):
        paragyro.simulate("no-such-scenario")
    with pytest.raises(paragyro.ArgumentError, match="not_an_effect"):
        paragyro.simulate("identify", effects=["not_an_effect=1"], duration_s=1.0)
    with pytest.raises(ValueError):  # ArgumentError is a ValueError too
        paragyro.simulate("identify", duration_s=-1.0)


def test_a_panic_is_an_internal_error():
    from paragyro import _native

    with pytest.raises(paragyro.InternalError, match="internal error .*: boom"):
        _native._panic_inside_the_guard("boom")
    # the interpreter goes on: the module still works
    assert paragyro.effects()[0][0] == "geometric_nonlinearity"
