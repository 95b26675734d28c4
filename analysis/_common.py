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
from pathlib import Path

import numpy as np
import pandas as pd


def parser(description: str, default_out: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description=description)
    p.add_argument("--data", type=Path, default=Path("data"), help="data root (data/<study>/sub-*/ses-*/trials.parquet)")
    p.add_argument("--out", type=Path, default=Path(default_out), help="output file")
    p.add_argument("--results", type=Path, default=Path("results"), help="directory for CSV/JSON statistics")
    return p


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
