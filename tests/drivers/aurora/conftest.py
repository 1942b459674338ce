"""Fixtures of the Aurora tests (helpers live in aurora_testkit.py)."""

from __future__ import annotations

import pytest
from aurora_testkit import make_plant

from drivers.plant import StaticPlant


@pytest.fixture
def plant() -> StaticPlant:
    return make_plant()
