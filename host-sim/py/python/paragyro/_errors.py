"""The exceptions of the package. The native module raises them with the message the CLI
prints (``file:line:col: context: message`` for a record or a scenario) and its parts as
attributes; they pickle with those attributes (a Dask worker's error reaches the client
whole)."""

from __future__ import annotations

from typing import Optional

__all__ = [
    "ParagyroError",
    "RecordError",
    "ScenarioError",
    "ArgumentError",
    "SimulationError",
    "RunError",
    "DiagnosisError",
    "InternalError",
]


class ParagyroError(Exception):
    """Base of every error the package raises.

    Attributes: ``message`` (the CLI's text), ``path`` (the file it concerns, if any),
    ``line`` and ``column`` (1-based, where known: the column is the field number on a
    record's header and data rows, the character position on its ``#`` lines), ``context``
    (``column 'x1_re_um'``, ``field 'plant.wy2'``, …) and ``kind`` (``number``, ``time``,
    ``header``, … for a record; ``parse``, ``invalid``, … for a scenario).
    """

    def __init__(
        self,
        message: str,
        path: Optional[str] = None,
        line: Optional[int] = None,
        column: Optional[int] = None,
        context: Optional[str] = None,
        kind: Optional[str] = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.path = path
        self.line = line
        self.column = column
        self.context = context
        self.kind = kind

    def __reduce__(self):  # keep the attributes through pickle (Dask, multiprocessing)
        return (
            type(self),
            (self.message, self.path, self.line, self.column, self.context, self.kind),
        )

    def __str__(self) -> str:
        return self.message


class RecordError(ParagyroError):
    """A record that cannot be read or written (host-sim/sim/record-format.md, "Errors")."""


class ScenarioError(ParagyroError):
    """A scenario (built-in name or TOML) that cannot be loaded."""


class ArgumentError(ParagyroError, ValueError):
    """An argument the CLI's parser would refuse (an effect spec, a precision, …)."""


class SimulationError(ParagyroError):
    """A simulation that failed (``paragyro-sim record``'s exit 1)."""


class RunError(ParagyroError):
    """A run of the core or of the rate-response measurements that failed."""


class DiagnosisError(ParagyroError):
    """A diagnosis that failed (``paragyro-sim diagnose``'s exit 1)."""


class InternalError(ParagyroError):
    """A panic in the Rust code, caught at the boundary (a bug: please report it)."""
