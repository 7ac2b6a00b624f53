"""The lot on Dask: a LocalCluster of two worker processes, nine records (eight devices and
a malformed file), one row per record equal to the CLI's report.json field for field, a
worker killed mid-lot, Parquet read back by pandas and polars."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pandas as pd
import pytest

import paragyro
import paragyro.lot
from conftest import DURATION_S

distributed = pytest.importorskip("distributed")

#: The lot: (seed, effects) per device; clean ones and library effects.
DEVICES = [
    (11, {}),
    (12, {"nonlinear_damping": 2e-5}),
    (13, {"feedthrough": 1e-3}),
    (14, {}),
    (15, {"nonlinear_damping": 1e-4}),
    (16, {"feedthrough": 5e-4}),
    (17, {}),
    (18, {"nonlinear_damping": 5e-5}),
]


@pytest.fixture(scope="module")
def lot_paths(rec_dir):
    """The lot's folder (its own: `paragyro-sim lot` diagnoses every CSV in it)."""
    (rec_dir / "lot").mkdir()
    paths = []
    for seed, eff in DEVICES:
        p = rec_dir / "lot" / f"lot-{seed}.csv"
        paragyro.simulate("identify", seed=seed, duration_s=DURATION_S, effects=eff, out=p)
        paths.append(p)
    bad = rec_dir / "lot" / "lot-bad.csv"
    text = paths[0].read_text().replace("# fs_hz: 500", "# fs_hz: fast", 1)
    bad.write_text(text)
    return paths + [bad]


@pytest.fixture(scope="module")
def client():
    cluster = distributed.LocalCluster(
        n_workers=2,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",
        env=dict(paragyro.lot.WORKER_ENV),
    )
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


def same(a, b) -> bool:
    """Equal, a missing value (None, NaN) only to a missing one."""
    missing = lambda v: v is None or (isinstance(v, float) and np.isnan(v))  # noqa: E731
    return (missing(a) and missing(b)) or a == b


def check_row_against_cli(row: dict, report: dict) -> None:
    """Every field of the row that report.json has, equal (the same float64)."""
    assert same(row["error"], None)
    assert row["verdict"] == report["verdict"]
    assert same(row["secondary"], (report.get("secondary") or {}).get("effect"))
    assert row["closest_library_effect"] == report["closest_library_effect"]
    for k in ("gap_before", "gap_after", "gap_closure", "gap_fraction_of_baseline",
              "unexplained_above_noise", "residual_over_noise", "samples", "model", "seconds"):  # fmt: skip
        assert row[k] == report[k], k
    assert row["noise_energy_ratio"] == report["parameter_face"]["noise_energy_ratio"]
    assert same(row["output_error_closure"], None)  # resimulate=False: none
    testable = [c for c in report["ranking"] if c["untestable"] is None]
    for i, c in enumerate(testable[:3]):
        for f, g in (("effect", "effect"), ("size", "size"), ("sigma", "size_sigma"), ("gap_closure", "gap_closure")):
            assert same(row[f"top{i + 1}_{f}"], c[g]), (i, f)
    assert len(report["parameter_face"]["parameters"]) == 14
    for p in report["parameter_face"]["parameters"]:
        for f, g in (("model", "model"), ("device", "device"), ("sigma", "sigma"),
                     ("rel", "relative"), ("rel_sigma", "relative_sigma"), ("t", "t")):  # fmt: skip
            assert same(row[f"{p['name']}_{f}"], p[g]), (p["name"], f)


def test_lot_rows_are_the_clis_reports(lot_paths, client, cli, tmp_path):
    killed = []

    def kill_a_busy_worker(i, row):
        # after the first row: SIGKILL a worker that is running a record right now
        if killed:
            return
        busy = [w for w, keys in client.processing().items() if keys]
        if not busy:
            return
        pids = client.run(os.getpid, workers=busy[:1])
        pid = next(iter(pids.values()))
        # its tasks read before the kill: the scheduler may drop a dead worker at once
        keys = sorted(client.processing().get(busy[0], ()))
        os.kill(pid, signal.SIGKILL)
        killed.append((busy[0], pid, keys))

    out = tmp_path / "lot.parquet"
    df = paragyro.lot.diagnose(
        lot_paths, client=client, out=out, resimulate=False, retries=2, on_row=kill_a_busy_worker
    )
    assert killed, "no worker was busy after the first row: nothing was killed"
    # one row per record, in order, none lost with the worker
    assert len(df) == len(lot_paths)
    assert list(df["path"]) == [str(p) for p in lot_paths]
    assert df["error"].iloc[:-1].isna().all(), df["error"].tolist()
    # the malformed record is a row with the CLI's located error
    bad = df.iloc[-1]
    assert bad["error"] == f"{lot_paths[-1]}:4:10: header 'fs_hz': expected a positive number, found 'fast'"
    assert bad["record"] == "lot-bad.csv" and same(bad["verdict"], None)
    # every device's row is the CLI's report.json, field for field (its wall time aside)
    rows = df.to_dict("records")
    for p, row in zip(lot_paths[:-1], rows[:-1]):
        cli("diagnose", p, "--out", tmp_path / p.stem, "--no-resim")
        report = json.loads((tmp_path / p.stem / "report.json").read_text())
        report["seconds"] = row["seconds"]
        check_row_against_cli(row, report)
    verdicts = dict(zip([s for s, _ in DEVICES], df["verdict"]))
    assert verdicts[12] == "nonlinear_damping" and verdicts[13] == "feedthrough"
    # Parquet: the same rows through pandas and polars
    back = pd.read_parquet(out)
    pd.testing.assert_frame_equal(back, df)
    pl = pytest.importorskip("polars")
    pdf = pl.read_parquet(out)
    assert pdf.height == len(df) and pdf.columns == list(df.columns)
    assert pdf["verdict"].to_list()[:-1] == df["verdict"].tolist()[:-1]
    assert pdf["wy2_sigma"].to_list()[:-1] == df["wy2_sigma"].tolist()[:-1]
    assert pdf["samples"].dtype == pl.Int64 and pdf["samples"].to_list()[-1] is None


def test_the_clis_lot_gives_the_same_rows(lot_paths, tmp_path, cli):
    """`paragyro-sim lot` (rayon) and `paragyro.lot` (Dask) on the same folder: the same
    rows, column for column, but for the wall times."""
    out = tmp_path / "cli.parquet"
    cli("lot", lot_paths[0].parent, "--out", out, "--no-resim", "--jobs", "2")
    theirs = pd.read_parquet(out)
    for name, kind in paragyro.lot.columns():  # pandas reads an INT64 column with nulls as float64
        if kind == "i64":
            theirs[name] = theirs[name].astype("Int64")
    ours = paragyro.lot.diagnose(lot_paths, n_workers=2, resimulate=False)
    assert list(ours.columns) == list(theirs.columns)
    timing = [c for c in ours.columns if c == "seconds" or c.startswith("time_")]
    assert len(timing) >= 9
    pd.testing.assert_frame_equal(ours.drop(columns=timing), theirs.drop(columns=timing))


def test_a_scheduler_address_runs_the_lot_on_that_cluster(lot_paths, client):
    """A scheduler address (as for a real cluster) connects a client of its own to it: the
    same rows as with the client object, the tasks ran on that cluster's workers, and the
    cluster is left running (only the lot's own client is closed)."""
    addr = client.scheduler.address
    assert isinstance(addr, str) and addr.startswith("tcp://")
    before = sum(client.run(lambda dask_worker: len(dask_worker.data) + dask_worker.state.executed_count).values())
    by_address = paragyro.lot.diagnose(lot_paths[:3], client=addr, resimulate=False)
    after = sum(client.run(lambda dask_worker: len(dask_worker.data) + dask_worker.state.executed_count).values())
    assert after >= before + 3, (before, after)
    assert client.status == "running" and len(client.scheduler_info()["workers"]) == 2
    by_client = paragyro.lot.diagnose(lot_paths[:3], client=client, resimulate=False)
    timing = [c for c in by_client.columns if c == "seconds" or c.startswith("time_")]
    pd.testing.assert_frame_equal(by_address.drop(columns=timing), by_client.drop(columns=timing))
    assert list(by_address["verdict"][1:]) == ["nonlinear_damping", "feedthrough"]
