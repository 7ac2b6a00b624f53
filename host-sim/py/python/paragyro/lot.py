"""A lot of records diagnosed on Dask distributed: one task per record, one row per device.

``paragyro.lot.diagnose(paths)`` starts a ``LocalCluster`` of worker processes (or uses
the ``distributed.Client`` or scheduler address given), submits one task per record with
Dask's ``retries`` (a record whose worker dies is re-run on another: the scheduler
reschedules it, up to ``distributed.scheduler.allowed-failures`` times), and gathers one
row per device in the order of ``paths``. A record that cannot be read or diagnosed is a
row with its ``error`` (and the file, line and column in the message), never dropped.
With ``out`` the rows are written as Parquet (pyarrow), readable by pandas and polars.
"""

from __future__ import annotations

import json
import os
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

from . import _native

__all__ = ["diagnose", "diagnose_one", "columns", "write_parquet"]

PathLike = Union[str, "os.PathLike[str]"]

#: The environment of the lot's own worker processes: one thread each (the diagnosis's
#: rayon stages would otherwise take every core in every worker).
WORKER_ENV = {"RAYON_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}


def error_row(path: str, error: str) -> Dict[str, Any]:
    """The row of a record whose task failed past its retries (the other columns null)."""
    return {"record": os.path.basename(path), "path": path, "error": error}


def diagnose_one(
    path: str,
    model: Optional[str] = None,
    resimulate: bool = True,
    confirm_runs: Optional[int] = None,
    reports: Optional[str] = None,
) -> Dict[str, Any]:
    """One device's row: ``paragyro_lot::diagnose_path``, the CLI's lot's own function (the
    lot's task). It never raises for a bad record: the error is the row's ``error``, with
    the file, line and column of the reader's message."""
    return json.loads(
        _native.lot_row(path, model=model, resimulate=resimulate, confirm_runs=confirm_runs, reports=reports)
    )


def columns() -> List[Tuple[str, str]]:
    """The row's columns in order, with their type (``str``, ``f64``, ``i64``):
    ``paragyro_lot::columns``, the Parquet schema of the Rust lot."""
    return list(_native.lot_columns())


def _client(client: Any, n_workers: Optional[int]):
    """(client, things to close): the given client, a client of a scheduler address, or a
    new LocalCluster of worker processes."""
    from distributed import Client, LocalCluster

    if client is None:
        cluster = LocalCluster(
            n_workers=n_workers or os.cpu_count() or 1,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            env=dict(WORKER_ENV),
        )
        c = Client(cluster)
        return c, [c, cluster]
    if isinstance(client, str):
        c = Client(client)
        return c, [c]
    return client, []


def diagnose(
    paths: Iterable[PathLike],
    client: Any = None,
    out: Optional[PathLike] = None,
    retries: int = 2,
    model: Optional[str] = None,
    resimulate: bool = True,
    confirm_runs: Optional[int] = None,
    reports: Optional[PathLike] = None,
    n_workers: Optional[int] = None,
    on_row: Optional[Callable[[int, Dict[str, Any]], None]] = None,
) -> Any:
    """Diagnoses every record of ``paths`` on Dask; returns a pandas DataFrame, one row per
    record in the order of ``paths`` (``error`` set where it failed).

    ``client``: None (a ``LocalCluster`` of ``n_workers`` processes, one thread each, closed
    afterwards), a ``distributed.Client`` or a scheduler address (``"tcp://host:8786"``);
    ``retries``: Dask's retries of a task that raised; a task whose worker died is
    rescheduled by the scheduler. ``model``, ``resimulate``, ``confirm_runs``: as
    :func:`paragyro.diagnose`; ``reports``: write each device's report into
    ``reports/<record stem>/`` (a folder the workers can reach). ``out``: also write the
    rows as Parquet. ``on_row(i, row)`` is called in the client as each row arrives
    (progress). The columns are :func:`columns` (the Rust lot's), typed: text, float64,
    nullable Int64.
    """
    import pandas as pd
    from distributed import as_completed

    paths = [os.path.abspath(os.fspath(p)) for p in paths]
    if model is not None:
        _native.check_scenario(model)  # a bad model: one ScenarioError here, not a lot of error rows
    rep = None if reports is None else os.path.abspath(os.fspath(reports))
    c, owned = _client(client, n_workers)
    try:
        futures = c.map(
            diagnose_one,
            paths,
            model=model,
            resimulate=resimulate,
            confirm_runs=confirm_runs,
            reports=rep,
            retries=retries,
            pure=False,
            key=[f"paragyro-lot-{i}-{os.path.basename(p)}-{os.getpid()}-{time.time_ns()}" for i, p in enumerate(paths)],
        )
        index = {f.key: i for i, f in enumerate(futures)}
        rows: List[Optional[Dict[str, Any]]] = [None] * len(paths)
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                rows[i] = fut.result()
            except Exception as e:  # the task failed past its retries, or its workers died
                rows[i] = error_row(paths[i], f"{type(e).__name__}: {e}")
            if on_row is not None:
                on_row(i, rows[i])
    finally:
        for x in owned:
            x.close()
    df = _frame(rows)
    if out is not None:
        write_parquet(df, out)
    return df


def _frame(rows: List[Optional[Dict[str, Any]]]) -> Any:
    """The rows as a DataFrame with the Rust lot's columns, in its order and types (text:
    pandas' ``str`` from pandas 3 on, object before; float64 with NaN; nullable Int64), so
    that a Parquet file written from it reads back equal."""
    import pandas as pd

    text = "str" if int(pd.__version__.split(".")[0]) >= 3 else object

    data: Dict[str, Any] = {}
    for name, kind in columns():
        vals = [(r or {}).get(name) for r in rows]
        if kind == "f64":
            data[name] = pd.array([float("nan") if v is None else v for v in vals], dtype="float64")
        elif kind == "i64":
            data[name] = pd.array(vals, dtype="Int64")
        else:
            data[name] = pd.Series(vals, dtype=text)
    return pd.DataFrame(data)


def write_parquet(df: Any, out: PathLike) -> None:
    """Writes the lot's rows as Parquet (pyarrow), creating the parent directory."""
    p = os.fspath(out)
    parent = os.path.dirname(p)
    if parent:
        os.makedirs(parent, exist_ok=True)
    df.to_parquet(p, engine="pyarrow", index=False)
