"""Helpers for the study tests: tiny specs (the short plan, a handful of cells, each a
few seconds) and the study command."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from hydrojet_bench.studies.cell import ROW_COLUMNS
from hydrojet_bench.studies.store import RowStore

# A cell that raises in the twin: the study must record it and go on.
BOOM_EFFECT = '''
from hydrojet_bench.effects import EffectParameter


class Boom:
    name = "boom"
    explanation = "raises inside the twin's solve"
    parameters = (EffectParameter("size", 0.0, 0.0, 1.0, "1", "anything above 0 raises"),)
    uses_actuation = False

    def apply(self, problem, values):
        if values["size"] > 0.0:
            raise RuntimeError("boom inside the twin")
'''


def write_spec(folder: Path, body: str, name: str = "tiny.toml") -> Path:
    (folder / "boom.py").write_text(BOOM_EFFECT)
    path = folder / name
    path.write_text(textwrap.dedent(body))
    return path


TINY = """
    plans = ["short"]
    seeds = [0, 1]

    [[effects]]
    effect = "jet_gain"
    parameter = "gain_1"
    sizes = [0.7]
"""

WITH_BOOM = TINY + """
    [[effects]]
    effect = "boom.py:Boom"
    parameter = "size"
    sizes = [0.5]
"""


def study_command(*args: str) -> list[str]:
    return [sys.executable, "-m", "hydrojet_bench.cli", "study", *args]


def run_study(*args: str, timeout_s: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run(study_command(*args), capture_output=True, text=True, timeout=timeout_s)


def stored_rows(folder: Path):
    return RowStore(folder, ROW_COLUMNS, "cell_id").table()
