"""The README's session runs as written (the ```python block of "## A session")."""

from __future__ import annotations

import re
import runpy
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def session_block() -> str:
    text = README.read_text()
    section = re.search(r"^## A session.*?(?=^## )", text, flags=re.S | re.M)
    assert section, f"no '## A session' section in {README}"
    blocks = re.findall(r"^```python\n(.*?)^```", section.group(0), flags=re.S | re.M)
    assert len(blocks) == 1, f"expected one python block in '## A session', found {len(blocks)}"
    return blocks[0]


def test_the_readme_session_runs(tmp_path, monkeypatch, capsys):
    script = tmp_path / "session.py"
    script.write_text(session_block())
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(script), run_name="__main__")
    out = capsys.readouterr().out
    assert "nonlinear_damping nonlinear_damping" in out and "rate 1" in out
    assert (tmp_path / "out" / "diag" / "report.json").exists()
    assert (tmp_path / "out" / "diag" / "report.md").exists()
