"""Shared plumbing of the study analysis scripts: arguments, results files, JSON.

Every script: ``--data DIR`` (the data root), ``--out PATH`` (a PNG, PDF beside it, or
the CSV for the fit cache), ``--results DIR`` (machine-readable statistics; default
``results``). Scripts are run as ``python analysis/<name>.py``, so this module is found
on ``sys.path[0]``.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd


def parser(description: str, default_out: str, study: str | None = None) -> argparse.ArgumentParser:
    """The common arguments; with ``study``, also ``--study`` (the data/<study> folder, i.e. the
    protocol's ``study.name``; default ``study``), so a user's own protocol of that kind can be analysed."""
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--data", type=Path, default=Path("data"), help="data root (data/<study>/sub-*/ses-*/trials.parquet)")
    p.add_argument("--out", type=Path, default=Path(default_out), help="output file")
    p.add_argument("--results", type=Path, default=Path("results"), help="directory for CSV/JSON statistics")
    if study is not None:
        p.add_argument("--study", default=study, help=f"study name (the protocol's study.name; default {study})")
    return p


def run(main: Callable[[], int]) -> int:
    """Run a script's ``main``; bad input (a UserError) is one line on stderr and its exit code
    (2), not a traceback."""
    from psyop.errors import UserError

    try:
        return main()
    except UserError as error:
        print(f"{Path(sys.argv[0]).name}: error: {error}", file=sys.stderr)
        return error.exit_code


def _clean(value):
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, (np.floating, float)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def write_json(path: Path, payload: dict) -> Path:
    """Write ``payload`` as JSON (NaN/inf -> null); creates the directory."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(_clean(payload), indent=2) + "\n")
    return path


def read_fits(path: Path) -> pd.DataFrame:
    """Read a psychometric fit cache (results/<study>_fits.csv): ``flags`` '' when none, ``status`` required."""
    fits = pd.read_csv(path, dtype={"participant": str, "flags": str, "status": str}, keep_default_na=False,
                       na_values=[""])
    fits["flags"] = fits["flags"].fillna("").astype(str)
    if "status" not in fits:
        from psyop.errors import UserError

        raise UserError("fit cache has no 'status' column (written by an older psyop): delete it and rerun "
                        "analysis/fit_psychometric.py", str(path))
    return fits
