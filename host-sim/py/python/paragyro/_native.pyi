# The native module paragyro._native (host-sim/py/src). Use the package `paragyro`.
from typing import Any, List, Optional, Sequence, Tuple

VERSION: str

_Parts = Tuple[List[Tuple[str, Any]], List[Tuple[str, bytearray]], List[str]]

class NativeDiagnosis:
    def report_json(self) -> str: ...
    def report_markdown(self) -> str: ...
    def write_report(self, dir: str) -> List[str]: ...

def read_record(path: str) -> _Parts: ...
def parse_record_text(text: str, source: str) -> _Parts: ...
def write_record(header: dict, columns: dict, path: str) -> None: ...
def effect_names() -> List[Tuple[str, str, bool]]: ...
def simulate(
    scenario: str,
    seed: Optional[int] = None,
    effects: Sequence[str] = ...,
    temp: Optional[Tuple[float, float]] = None,
    rate_table: bool = False,
    duration_s: Optional[float] = None,
    out: Optional[str] = None,
) -> Tuple[_Parts, str, List[str]]: ...
def run_core(header: dict, columns: dict, source: str, precision: str = "f32") -> List[Tuple[str, bytearray]]: ...
def diagnose_path(
    path: str, model: Optional[str] = None, resimulate: bool = True, confirm_runs: Optional[int] = None
) -> Tuple[NativeDiagnosis, List[str]]: ...
def diagnose_record(
    header: dict,
    columns: dict,
    name: str,
    model: Optional[str] = None,
    resimulate: bool = True,
    confirm_runs: Optional[int] = None,
) -> NativeDiagnosis: ...
def rate_response(
    seed: int = 1,
    precision: str = "f32",
    allan_s: Optional[float] = None,
    allan_zero_memory_s: Optional[float] = None,
    allan_forgetting: Optional[float] = None,
    allan_settle_s: float = 600.0,
    allan_warm_start: bool = False,
    out: Optional[str] = None,
) -> Tuple[str, str, List[str]]: ...
def lot_columns() -> List[Tuple[str, str]]: ...
def lot_row(
    path: str,
    model: Optional[str] = None,
    resimulate: bool = True,
    confirm_runs: Optional[int] = None,
    reports: Optional[str] = None,
) -> str: ...
def check_scenario(name: str) -> None: ...
def _panic_inside_the_guard(message: str) -> None: ...
