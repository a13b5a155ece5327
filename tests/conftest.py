"""Shared pytest fixtures; the helpers live in tests/helpers.py."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator: random test points are reproducible."""
    return np.random.default_rng(20240521)
