"""``paragyro.Record``: a record (host-sim/sim/record-format.md) as a header dict and numpy
columns."""

from __future__ import annotations

import os
from typing import Any, Dict, List, Optional, Union

import numpy as np

from . import _native

PathLike = Union[str, "os.PathLike[str]"]

#: The required columns, in the order writers use.
REQUIRED_COLUMNS = (
    "t_s", "pump_hz", "pump_amp_v", "ax_mps2", "ay_mps2",
    "x0_um", "x1_re_um", "x1_im_um", "x2_re_um", "x2_im_um", "x3_re_um", "x3_im_um",
    "y0_um", "y1_re_um", "y1_im_um", "y2_re_um", "y2_im_um", "y3_re_um", "y3_im_um",
)  # fmt: skip
#: The optional columns (NaN where a field is empty, i.e. unknown).
OPTIONAL_COLUMNS = ("temp_c", "rate_ref_dps")


class Record:
    """A record: ``header`` (dict: ``format``, ``f0_hz``, ``l0_um``, ``fs_hz``,
    ``lockin_lpf_order``, ``lockin_lpf_hz``, ``pump_amp_ref_v`` as numbers, then the extra
    keys as text, in file order), ``columns`` (dict of float64 numpy arrays: the 19
    required columns, then ``temp_c`` and ``rate_ref_dps`` when the record has them, NaN
    where a field is empty), ``warnings`` (the reader's), ``name`` (the file name, used in
    reports and errors) and, for a simulated record, ``truth`` (the truth file's dict,
    never part of the record)."""

    def __init__(
        self,
        header: Dict[str, Any],
        columns: Dict[str, np.ndarray],
        warnings: Optional[List[str]] = None,
        name: str = "record",
        truth: Optional[Dict[str, Any]] = None,
    ) -> None:
        self.header = dict(header)
        self.columns = {k: np.asarray(v, dtype=np.float64) for k, v in columns.items()}
        self.warnings = list(warnings or [])
        self.name = name
        self.truth = truth

    @classmethod
    def _from_native(cls, parts: Any, name: str, truth: Optional[Dict[str, Any]] = None) -> "Record":
        header, columns, warnings = parts
        cols = {k: np.frombuffer(v, dtype=np.float64) for k, v in columns}
        return cls(dict(header), cols, warnings, name=name, truth=truth)

    def _native_parts(self) -> "tuple[Dict[str, Any], Dict[str, bytes]]":
        cols = {k: np.ascontiguousarray(v, dtype=np.float64).tobytes() for k, v in self.columns.items()}
        return self.header, cols

    def __len__(self) -> int:
        return len(self.columns["t_s"]) if "t_s" in self.columns else 0

    def __repr__(self) -> str:
        return f"<paragyro.Record {self.name!r}: {len(self)} samples, {self.duration_s:.3f} s, columns {list(self.columns)}>"

    @property
    def duration_s(self) -> float:
        """From the first to the last sample, s."""
        t = self.columns.get("t_s")
        return float(t[-1] - t[0]) if t is not None and len(t) else 0.0

    def to_pandas(self) -> "Any":
        """The columns as a pandas DataFrame (in record order); the header is in
        ``df.attrs["header"]``, so ``write_record(df, path)`` writes the same record."""
        import pandas as pd

        df = pd.DataFrame({k: v for k, v in self.columns.items()})
        df.attrs["header"] = dict(self.header)
        df.attrs["name"] = self.name
        return df

    @classmethod
    def from_pandas(cls, df: Any, header: Optional[Dict[str, Any]] = None, name: Optional[str] = None) -> "Record":
        """A record from a DataFrame with the record's columns; ``header`` defaults to
        ``df.attrs["header"]`` (set by :meth:`to_pandas`)."""
        h = header if header is not None else df.attrs.get("header")
        if h is None:
            from ._errors import ArgumentError

            raise ArgumentError("a DataFrame needs a header: pass header=... or set df.attrs['header']")
        cols = {str(k): df[k].to_numpy(dtype=np.float64) for k in df.columns}
        return cls(h, cols, name=name or df.attrs.get("name", "record"))

    def write(self, path: PathLike) -> None:
        """Writes the record (as :func:`paragyro.write_record`)."""
        write_record(self, path)


def read_record(path: PathLike) -> Record:
    """Reads a record file. Errors are :class:`paragyro.RecordError` with the file, line and
    column ``paragyro-sim`` reports."""
    p = os.fspath(path)
    return Record._from_native(_native.read_record(p), name=os.path.basename(p))


def parse_record(text: str, source: str = "record") -> Record:
    """Parses a record's text (``source`` names it in errors)."""
    return Record._from_native(_native.parse_record_text(text, source), name=source)


def as_record(obj: Any) -> Record:
    """A :class:`Record` from a Record, a pandas DataFrame (its header in
    ``df.attrs["header"]``) or a path."""
    if isinstance(obj, Record):
        return obj
    if isinstance(obj, (str, os.PathLike)):
        return read_record(obj)
    if hasattr(obj, "attrs") and hasattr(obj, "columns"):
        return Record.from_pandas(obj)
    from ._errors import ArgumentError

    raise ArgumentError(f"expected a paragyro.Record, a DataFrame or a path, got {type(obj).__name__}")


def write_record(record: Any, path: PathLike) -> None:
    """Writes a record (a :class:`Record` or a DataFrame from :meth:`Record.to_pandas`) as
    the paragyro writer does (shortest round-trip numbers: it reads back bit for bit),
    after the reader's checks: what it would refuse to read is a
    :class:`paragyro.RecordError` naming its line and column, and nothing is written."""
    rec = as_record(record)
    header, cols = rec._native_parts()
    _native.write_record(header, cols, os.fspath(path))
