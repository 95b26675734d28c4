"""Study power by simulation: whole simulated studies through the real compile -> session ->
analysis path, replicated on local processes or a Dask cluster (``psyop power``)."""

from psyop.power.run import PowerRun, run_power

__all__ = ["PowerRun", "run_power"]
