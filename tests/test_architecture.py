"""The layer rules hold: import-linter checks every contract in pyproject.toml's
[tool.importlinter] section (add a rule there, not here) and its report is the failure
message."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
_LINT = (
    "import sys\n"
    "from importlinter.cli import lint_imports\n"
    "sys.exit(lint_imports(config_filename=sys.argv[1], no_cache=True, no_logo=True))\n"
)


def lint_imports(config: Path) -> subprocess.CompletedProcess[str]:
    # The repository first on the path, so the tree under test is analysed and not an
    # installed copy of the packages.
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p)
    return subprocess.run(
        [sys.executable, "-c", _LINT, str(config)],
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": path, "COLUMNS": "160"},  # unwrapped report lines
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_import_contracts_are_kept() -> None:
    result = lint_imports(REPO / "pyproject.toml")
    report = result.stdout + result.stderr
    assert result.returncode == 0, report
