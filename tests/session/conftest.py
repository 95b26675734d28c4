"""Fixtures for session tests."""

from __future__ import annotations

from pathlib import Path

import pytest
from session_helpers import small_protocol


@pytest.fixture
def detection_small(tmp_path: Path) -> Path:
    return small_protocol(tmp_path, "detection", 1)
