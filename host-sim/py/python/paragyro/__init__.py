"""paragyro: the characterisation lab in Python.

Records (read, write, pandas), the simulated gyro (``simulate``), the core open-loop on a
record (``run_core``), the sim-to-real diagnosis (``diagnose``) and the rate-response
datasheet (``rate_response``), computed by the project's Rust crates (the same functions as
the ``paragyro-sim`` CLI: the same numbers, bit for bit); a lot of records on Dask in
:mod:`paragyro.lot`. Guide: host-sim/py/README.md.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._diagnosis import (
    Candidate,
    Diagnosis,
    Hypothesis,
    Limitation,
    OutputError,
    OutputErrorValues,
    Parameter,
    ParameterFace,
    Secondary,
)
from ._errors import (
    ArgumentError,
    DiagnosisError,
    InternalError,
    ParagyroError,
    RecordError,
    RunError,
    ScenarioError,
    SimulationError,
)
from ._record import (
    OPTIONAL_COLUMNS,
    REQUIRED_COLUMNS,
    Record,
    as_record,
    parse_record,
    read_record,
    write_record,
)

__version__: str = _native.VERSION

__all__ = [
    "Record", "read_record", "write_record", "parse_record", "simulate", "run_core",
    "diagnose", "rate_response", "effects", "Diagnosis", "Candidate", "Parameter",
    "ParameterFace", "Hypothesis", "Secondary", "OutputError", "OutputErrorValues",
    "Limitation", "ParagyroError", "RecordError", "ScenarioError", "ArgumentError",
    "SimulationError", "RunError", "DiagnosisError", "InternalError", "REQUIRED_COLUMNS",
    "OPTIONAL_COLUMNS", "__version__",
]  # fmt: skip

PathLike = Union[str, "os.PathLike[str]"]
Effects = Union[None, str, Sequence[str], Mapping[str, Union[float, Tuple[float, float]]]]


def effects() -> List[Tuple[str, str, bool]]:
    """The effects the simulator can add: ``(name, unit, in the diagnosis's library)``
    (``paragyro-sim effects``)."""
    return list(_native.effect_names())


def _effect_specs(effects: Effects) -> List[str]:
    """``NAME=SIZE[@PARAM]`` strings from a string, a list of them or a dict
    ``{name: size}`` / ``{name: (size, param)}``."""
    if effects is None:
        return []
    if isinstance(effects, str):
        return [effects]
    if isinstance(effects, Mapping):
        out = []
        for name, v in effects.items():
            if isinstance(v, (tuple, list)):
                size, param = v
                out.append(f"{name}={float(size)!r}@{float(param)!r}")
            else:
                out.append(f"{name}={float(v)!r}")
        return out
    return [str(e) for e in effects]


def _temperature(t: Any) -> Optional[Tuple[float, float]]:
    if t is None:
        return None
    if isinstance(t, str):
        a, sep, b = t.partition(":")
        if not sep:
            raise ArgumentError(f"'{t}': expected START_C:RISE_K, e.g. 25:5")
        try:
            return (float(a), float(b))
        except ValueError:
            raise ArgumentError(f"'{t}': START_C and RISE_K must be numbers") from None
    start, rise = t
    return (float(start), float(rise))


def simulate(
    scenario: str = "identify",
    effects: Effects = None,
    seed: Optional[int] = None,
    temperature: Union[None, str, Tuple[float, float]] = None,
    rate_table: bool = False,
    duration_s: Optional[float] = None,
    out: Optional[PathLike] = None,
) -> Record:
    """A simulated record, as ``paragyro-sim record SCENARIO``.

    ``scenario``: a built-in name or a scenario TOML; ``effects``: ``"NAME=SIZE"`` strings
    (``--effect``, ``paragyro.effects()`` lists them) or ``{name: size}``; ``seed``
    (``--seed``); ``temperature``: ``(start_c, rise_k)`` or ``"25:4"`` (``--temp``, a
    linear die temperature written as ``temp_c``); ``rate_table`` (``--rate-table``: the
    true rate as ``rate_ref_dps``); ``duration_s`` replaces the scenario's duration;
    ``out``: also write the record and its truth (``FILE.truth.json``) there. The truth is
    ``record.truth`` (a dict), never part of the record.
    """
    parts, truth, _files = _native.simulate(
        os.fspath(scenario),
        seed=seed,
        effects=_effect_specs(effects),
        temp=_temperature(temperature),
        rate_table=rate_table,
        duration_s=duration_s,
        out=None if out is None else os.fspath(out),
    )
    name = os.path.basename(os.fspath(out)) if out is not None else f"{os.path.basename(os.fspath(scenario))}.csv"
    return Record._from_native(parts, name=name, truth=json.loads(truth))


#: The integer columns of ``run_core``'s trace (the rest are floats).
_INT_COLUMNS = ("health", "events", "updates", "bad_samples", "resets_drive", "resets_sense")


def run_core(record: Any, precision: str = "f32") -> Any:
    """The core open-loop on a record, as ``paragyro-sim replay`` (``--precision``): a
    pandas DataFrame with the columns of its ``estimates.csv`` (``t_s``, ``pump_hz``,
    ``pump_scale``, θ̂ ``th11_est`` … ``th26_est``, ``rate_dps_est``, ``wy2_est``, ``health``,
    ``events``, ``pump_hz_cmd``, ``updates``, ``bad_samples``, ``resets_drive``,
    ``resets_sense``), one row per sample. ``record``: a Record, a DataFrame or a path."""
    import pandas as pd

    rec = as_record(record)
    header, cols = rec._native_parts()
    out = _native.run_core(header, cols, rec.name, precision)
    data: Dict[str, np.ndarray] = {}
    for name, buf in out:
        a = np.frombuffer(buf, dtype=np.float64)
        data[name] = a.astype(np.int64) if name in _INT_COLUMNS else a
    return pd.DataFrame(data)


def diagnose(
    record: Any,
    model: Optional[str] = None,
    resimulate: bool = True,
    confirm_runs: Optional[int] = None,
) -> Diagnosis:
    """The sim-to-real diagnosis of a record, as ``paragyro-sim diagnose`` (``--model``,
    ``--no-resim`` = ``resimulate=False``, ``--confirm-runs``): a typed
    :class:`Diagnosis` whose ``to_dict()`` is the CLI's report.json. ``record``: a path
    (read by the same reader as the CLI), a :class:`Record` or a DataFrame."""
    if isinstance(record, (str, os.PathLike)):
        native, warnings = _native.diagnose_path(
            os.fspath(record), model=model, resimulate=resimulate, confirm_runs=confirm_runs
        )
        return Diagnosis._from_native(native, warnings)
    rec = as_record(record)
    header, cols = rec._native_parts()
    native = _native.diagnose_record(
        header, cols, rec.name, model=model, resimulate=resimulate, confirm_runs=confirm_runs
    )
    return Diagnosis._from_native(native, rec.warnings)


def rate_response(
    seed: int = 1,
    precision: str = "f32",
    allan_s: Optional[float] = None,
    allan_zero_memory_s: Optional[float] = None,
    allan_forgetting: Optional[float] = None,
    allan_settle_s: float = 600.0,
    allan_warm_start: bool = False,
    out: Optional[PathLike] = None,
) -> Dict[str, Any]:
    """The rate channel's datasheet on the simulated device, as ``paragyro-sim
    rate-response`` (``--seed``, ``--precision``, ``--allan-s``,
    ``--allan-zero-memory-s``, ``--allan-forgetting``, ``--allan-settle-s``, ``--allan-warm-start``; with ``out`` it writes report.json, report.md and the PNGs
    there too): its report.json as a dict (``step``, ``frequency`` with
    ``bandwidth_3db_hz``, ``sines``, ``ramp``, ``g_sensitivity``, ``noise``, ``allan``), plus
    ``"markdown"``, the report's table."""
    text, md, _files = _native.rate_response(
        seed=seed,
        precision=precision,
        allan_s=allan_s,
        allan_zero_memory_s=allan_zero_memory_s,
        allan_forgetting=allan_forgetting,
        allan_settle_s=allan_settle_s,
        allan_warm_start=allan_warm_start,
        out=None if out is None else os.fspath(out),
    )
    report = json.loads(text)
    report["markdown"] = md
    return report
