"""Benchmarks of the Python package (not timed tests): the per-record overhead of
``paragyro.diagnose`` and of the Dask lot against the CLI on the same record, and the lot's
throughput with 1 and 2 worker processes. Numbers: host-sim/py/README.md, "Benchmarks".

    target/py-venv/bin/python host-sim/py/bench/bench_lot.py [--records 8] [--duration 10] [--reps 5]

Every diagnosis runs on one thread (RAYON_NUM_THREADS=1 for the CLI, this process and the
workers), so that 2 workers on 2 cores measure the lot's scaling and not the diagnosis's
own threads. The CLI is PARAGYRO_SIM_BIN or target/release/paragyro-sim.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ["RAYON_NUM_THREADS"] = "1"  # before the first diagnosis starts rayon's pool

import paragyro  # noqa: E402
import paragyro.lot  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]


def timed(f, reps):
    """Median and min wall time of `reps` calls of f(), s."""
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts), min(ts)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", type=int, default=8, help="records in the lot (default 8)")
    ap.add_argument("--duration", type=float, default=10.0, help="record length, s (default 10)")
    ap.add_argument("--reps", type=int, default=5, help="repeats of the single-record timings")
    ap.add_argument("--no-resim", action="store_true", help="diagnose without the re-simulation")
    a = ap.parse_args()
    sim = Path(os.environ.get("PARAGYRO_SIM_BIN", ROOT / "target" / "release" / "paragyro-sim"))
    if not sim.exists():
        print(f"no CLI at {sim}: cargo build --release -p paragyro-sim", file=sys.stderr)
        return 2
    tmp = Path(tempfile.mkdtemp(prefix="paragyro-bench-"))
    effects = [{}, {"nonlinear_damping": 2e-5}, {"feedthrough": 1e-3}, {"nonlinear_damping": 5e-5}]
    paths = []
    for i in range(a.records):
        p = tmp / f"dev-{i:03}.csv"
        paragyro.simulate("identify", seed=100 + i, duration_s=a.duration, effects=effects[i % 4], out=p)
        paths.append(p)
    rec = paths[1]
    flags = ["--no-resim"] if a.no_resim else []
    env = dict(os.environ)
    print(f"records: {a.records} × {a.duration:g} s `identify` (seeds 100…), resimulate={not a.no_resim}, "
          f"{os.cpu_count()} cores, RAYON_NUM_THREADS=1, load average {os.getloadavg()[0]:.1f}")  # fmt: skip

    # one record: the CLI (process, read, diagnose, report.json, report.md, plots) …
    out = tmp / "cli"
    cli = timed(lambda: subprocess.run([str(sim), "diagnose", str(rec), "--out", str(out), *flags],
                                       check=True, capture_output=True, env=env), a.reps)  # fmt: skip
    # … the package in this process, the diagnosis alone and with the same report written …
    resim = not a.no_resim
    seconds = []

    def py():
        seconds.append(paragyro.diagnose(str(rec), resimulate=resim).seconds)

    pyd = timed(py, a.reps)
    pyw = timed(lambda: paragyro.diagnose(str(rec), resimulate=resim).write_report(tmp / "py"), a.reps)
    inner = statistics.median(seconds)
    # … and one Dask task on a running one-worker LocalCluster (submit, run, gather)
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0",
                      env=dict(paragyro.lot.WORKER_ENV)) as cluster, Client(cluster) as client:  # fmt: skip
        paragyro.lot.diagnose([rec], client=client, resimulate=resim)  # warm the worker
        dask1 = timed(lambda: paragyro.lot.diagnose([rec], client=client, resimulate=resim), a.reps)
    print("\none record (median of %d, min), s:" % a.reps)
    print(f"  the diagnosis itself (report.json's `seconds`)       {inner:7.3f}")
    print(f"  paragyro-sim diagnose (process + report + plots)     {cli[0]:7.3f}  (min {cli[1]:.3f})")
    print(f"  paragyro.diagnose(path)                              {pyd[0]:7.3f}  (min {pyd[1]:.3f})  overhead {pyd[0] - inner:+.3f}")
    print(f"  paragyro.diagnose(path).write_report(dir)            {pyw[0]:7.3f}  (min {pyw[1]:.3f})  vs the CLI {pyw[0] - cli[0]:+.3f}")
    print(f"  paragyro.lot.diagnose([path]) on a running worker    {dask1[0]:7.3f}  (min {dask1[1]:.3f})  overhead {dask1[0] - inner:+.3f}")

    # the lot's throughput: a fresh LocalCluster of n workers (its start-up timed apart)
    print(f"\nthe lot ({a.records} records):")
    res = {}
    for n in (1, 2):
        t0 = time.perf_counter()
        with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                          env=dict(paragyro.lot.WORKER_ENV)) as cluster, Client(cluster) as client:  # fmt: skip
            client.wait_for_workers(n)
            t1 = time.perf_counter()
            df = paragyro.lot.diagnose(paths, client=client, resimulate=resim)
            t2 = time.perf_counter()
        assert df["error"].isna().all(), df["error"].tolist()
        res[n] = t2 - t1
        busy = df["seconds"].sum()
        print(f"  {n} worker(s): start-up {t1 - t0:5.2f} s, lot {t2 - t1:6.2f} s, "
              f"{a.records / (t2 - t1) * 60:6.1f} records/min, the diagnoses' own time {busy:6.2f} s, "
              f"overhead per record {(n * (t2 - t1) - busy) / a.records:+.3f} s")  # fmt: skip
    print(f"  scaling 1 → 2 workers: {res[1] / res[2]:.2f}× (load average now {os.getloadavg()[0]:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
