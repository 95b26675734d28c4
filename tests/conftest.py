"""Shared pytest configuration."""

from __future__ import annotations

import os

import matplotlib
from hypothesis import HealthCheck, settings

matplotlib.use("Agg")

# Property tests are derandomised in every run (make test, CI, a bare pytest): the same
# examples on every machine, so a red run is reproducible and a load spike cannot turn
# one red. No per-example deadline: a loaded machine makes examples slower, not wrong.
# To search fresh examples on purpose: PSYOP_HYPOTHESIS=explore pytest ...
settings.register_profile(
    "psyop",
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile("explore", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("explore" if os.environ.get("PSYOP_HYPOTHESIS") == "explore" else "psyop")
