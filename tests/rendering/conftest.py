"""Shared fixture for the renderer tests: one EGL context per test module."""

from __future__ import annotations

import pytest

from psyop.rendering.renderer import create_headless_context


@pytest.fixture(scope="module")
def gl_context():
    ctx = create_headless_context()
    yield ctx
    ctx.release()
