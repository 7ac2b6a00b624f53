"""``paragyro.Diagnosis``: report.json, typed. Every field is parsed from the same serde
JSON the CLI writes (``to_dict()`` is that JSON as a dict); the Rust result is kept so that
``write_report`` writes exactly ``paragyro-sim diagnose``'s files."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional


@dataclass(frozen=True)
class Secondary:
    """A second effect on top of the verdict's."""

    effect: str
    #: The share of the explainable gap it adds to the first one.
    added_closure: float


@dataclass(frozen=True)
class Candidate:
    """One library effect's result (report.json's ``ranking``, best first)."""

    effect: str
    #: Fitted size in the effect's unit (None when the record cannot test it) and its 1σ.
    size: Optional[float]
    size_sigma: Optional[float]
    #: Held-out gap closure (E0 − E_c)/(E0 − E_floor).
    gap_closure: float
    significant: bool
    energy_fraction: float
    delta_bic: float
    residual_explainable: float
    coherent_with: List[str]
    untestable: Optional[str]
    beat_hz: Optional[float] = None


@dataclass(frozen=True)
class Parameter:
    """One calibrated parameter of the device against the model (the parameter face)."""

    name: str
    model: float
    device: float
    #: 1σ of ``device`` (cluster-robust).
    sigma: float
    #: (device − model)/|model| and its 1σ (None when the model's value is 0).
    relative: Optional[float]
    relative_sigma: Optional[float]
    #: (device − model)/σ.
    t: float


@dataclass(frozen=True)
class Hypothesis:
    """A hypothesis of the parameter face (``tolerance`` first)."""

    name: str
    status: str
    size: Optional[float]
    sigma: Optional[float]
    detail: str


@dataclass(frozen=True)
class ParameterFace:
    parameters: List[Parameter]
    hypotheses: List[Hypothesis]
    rate_offset_dps: Optional[float]
    #: The record's noise against 1 pm/√Hz (energy ratio ν²).
    noise_energy_ratio: float
    resimulations: int

    def parameter(self, name: str) -> Parameter:
        """The parameter ``name`` (``wy2``, ``mu_x``, …)."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)


@dataclass(frozen=True)
class OutputErrorValues:
    drive: float
    sense: float
    combined: float
    above_noise: float


@dataclass(frozen=True)
class OutputError:
    """How far: the re-simulation's output error before and after the verdict's effect(s)."""

    held_out_span_s: List[float]
    before: OutputErrorValues
    after: OutputErrorValues
    closure: float
    closure_raw: float
    added: List[str]
    rate_dps: Optional[float]


@dataclass(frozen=True)
class Limitation:
    stage: str
    detail: str


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """A diagnosis (``paragyro.diagnose``): the verdict, the ranking, the parameter face,
    how far, the noise level; :meth:`to_dict` is report.json, :meth:`write_report` writes
    report.json, report.md and the plots."""

    #: ``none``, ``unknown`` or an effect's name.
    verdict: str
    secondary: Optional[Secondary]
    ranking: List[Candidate]
    parameter_face: ParameterFace
    #: Held-out regression gap before and after the verdict's effect(s), and 1 − after/before.
    gap_before: float
    gap_after: float
    gap_closure: float
    #: The re-simulation's output error (None with ``resimulate=False``).
    output_error: Optional[OutputError]
    #: Held-out residual per row over the record's own noise (about 1 at the noise).
    residual_over_noise: float
    model: str
    rate_source: str
    samples: int
    #: Wall time of the diagnosis and of each stage, s.
    seconds: float
    timing_s: Dict[str, float]
    limitations: List[Limitation]
    #: The reader's warnings (for a record read from a file).
    warnings: List[str] = field(default_factory=list)
    _json: str = field(default="", repr=False)
    _native: Any = field(default=None, repr=False)

    @property
    def noise_energy_ratio(self) -> float:
        """The record's noise against 1 pm/√Hz (energy ratio ν², the parameter face's)."""
        return self.parameter_face.noise_energy_ratio

    @property
    def top(self) -> Optional[Candidate]:
        """The best testable candidate."""
        return next((c for c in self.ranking if c.untestable is None), None)

    def to_dict(self) -> Dict[str, Any]:
        """report.json as a dict (a fresh copy: the same serde JSON the CLI writes)."""
        return json.loads(self._json)

    def to_json(self) -> str:
        """report.json's text, as the CLI writes it."""
        return self._json

    def markdown(self) -> str:
        """report.md's text."""
        return self._native.report_markdown()

    def write_report(self, dir: "str | os.PathLike[str]") -> List[str]:
        """Writes report.json, report.md and the PNGs into ``dir``; returns the files."""
        return list(self._native.write_report(os.fspath(dir)))

    @classmethod
    def _from_native(cls, native: Any, warnings: Optional[List[str]] = None) -> "Diagnosis":
        text = native.report_json()
        return cls._from_json(text, native, warnings or [])

    @classmethod
    def _from_json(cls, text: str, native: Any = None, warnings: Optional[List[str]] = None) -> "Diagnosis":
        r = json.loads(text)
        sec = r.get("secondary")
        face = r["parameter_face"]
        oe = r.get("output_error")
        return cls(
            verdict=r["verdict"],
            secondary=Secondary(sec["effect"], sec["added_closure"]) if sec else None,
            ranking=[Candidate(**c) for c in r["ranking"]],
            parameter_face=ParameterFace(
                parameters=[Parameter(**p) for p in face["parameters"]],
                hypotheses=[Hypothesis(**h) for h in face["hypotheses"]],
                rate_offset_dps=face.get("rate_offset_dps"),
                noise_energy_ratio=face["noise_energy_ratio"],
                resimulations=face["resimulations"],
            ),
            gap_before=r["gap_before"],
            gap_after=r["gap_after"],
            gap_closure=r["gap_closure"],
            output_error=None
            if oe is None
            else OutputError(
                held_out_span_s=oe["held_out_span_s"],
                before=OutputErrorValues(**oe["before"]),
                after=OutputErrorValues(**oe["after"]),
                closure=oe["closure"],
                closure_raw=oe["closure_raw"],
                added=oe["added"],
                rate_dps=oe.get("rate_dps"),
            ),
            residual_over_noise=r["residual_over_noise"],
            model=r["model"],
            rate_source=r["rate"]["source"],
            samples=r["samples"],
            seconds=r["seconds"],
            timing_s=dict(r["timing_s"]),
            limitations=[Limitation(**x) for x in r.get("limitations", [])],
            warnings=list(warnings or []),
            _json=text,
            _native=native,
        )
