"""Fixtures for the study tests: tiny specs in a temporary folder."""

from __future__ import annotations

from pathlib import Path

import pytest
from study_helpers import TINY, WITH_BOOM, write_spec


@pytest.fixture
def tiny_spec(tmp_path: Path) -> Path:
    return write_spec(tmp_path, TINY)


@pytest.fixture
def spec_with_boom(tmp_path: Path) -> Path:
    return write_spec(tmp_path, WITH_BOOM)
