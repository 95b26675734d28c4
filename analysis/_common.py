"""Shared plumbing of the study analysis scripts: arguments, results files, JSON.

Every script: ``--data DIR`` (the data root), ``--study NAME`` (the data/<NAME> folder, i.e. the
protocol's ``study.name``), ``--out PATH`` (a PNG, PDF beside it, or the CSV for the fit cache),
``--results DIR`` (machine-readable statistics; default ``results``). Every output is named after
the study (``results/<study>_<what>.json``, ``figures/<study>_<what>.png``) and every results JSON
records the study, its response kind and the protocol hashes its sessions ran, so that
analysis/results_table.py puts only the paper's protocols in the paper's rows. Scripts are run as
``python analysis/<name>.py``, so this module is found on ``sys.path[0]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd



class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are one line and exit 2 (no usage block)."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def parser(description: str, default_out: str | None, study: str | None = None) -> argparse.ArgumentParser:
    """The common arguments; with ``study``, also ``--study`` (the data/<study> folder, i.e. the
    protocol's ``study.name``; default ``study``), so a user's own protocol of that kind can be analysed.
    ``default_out`` may hold ``{study}``; None: ``--out`` defaults to nothing (the script names it)."""
    p = _Parser(description=description)
    p.add_argument("--data", type=Path, default=Path("data"), help="data root (data/<study>/sub-*/ses-*/trials.parquet)")
    p.add_argument("--out", type=Path, default=None,
                   help=f"output file (default {default_out})" if default_out else "output file")
    p.set_defaults(default_out=default_out)
    p.add_argument("--pool-protocols", action="store_true", default=os.environ.get("PSYOP_POOL_PROTOCOLS") == "1",
                   help="analyse sessions of a study that ran different protocol versions (hashes) together, on "
                        "purpose (default: refused; `make figures POOL=1` sets PSYOP_POOL_PROTOCOLS=1)")
    p.add_argument("--results", type=Path, default=Path("results"), help="directory for CSV/JSON statistics")
    if study is not None:
        p.add_argument("--study", default=study, help=f"study name (the protocol's study.name; default {study})")
    return p


def out_path(args: argparse.Namespace) -> Path:
    """``--out``, else the script's default named after ``--study``."""
    if args.out is not None:
        return args.out
    return Path(args.default_out.format(study=getattr(args, "study", ""), results=args.results))


def results_file(results: Path, study: str, what: str = "", ext: str = "json") -> Path:
    """``results/<study>_<what>.<ext>`` (``results/<study>.<ext>`` without ``what``): every results
    file is named after its study.

    Examples
    --------
    >>> results_file(Path("results"), "mystudy", "thresholds").as_posix()
    'results/mystudy_thresholds.json'
    """
    return results / (f"{study}_{what}.{ext}" if what else f"{study}.{ext}")


def provenance(facts, analysis: str, pool_protocols: bool = False) -> dict:
    """The keys every results JSON starts with: which study, its response kind, which analysis
    wrote it, the protocol hashes its sessions ran and the simulated observers that answered them (``observers``:
    session.json's ``observer`` kinds; empty where people answered) (psyop.statistics.studies.StudyFacts).

    Sessions under more than one protocol hash are refused (a UserError naming the hashes and each
    version's ``--study <study>@<hash12>``, which `make figures` runs) unless ``pool_protocols``
    (``--pool-protocols``, ``make figures POOL=1``); pooled, the JSON says so. One version of several
    (``--study <study>@<hash12>``) records the folder's versions under ``study_protocol_versions``."""
    from psyop.statistics.protocol_versions import unit_name

    hashes = list(facts.protocol_sha256)
    if len(hashes) > 1 and not pool_protocols:
        from psyop.errors import UserError

        raise UserError(f"study {facts.name!r}: its sessions ran {len(hashes)} protocol versions (sha256 "
                        f"{', '.join(h[:12] for h in hashes)}); analyse each version apart with --study "
                        f"{' / '.join(unit_name(facts.name, h) for h in hashes)} (as `make figures` does) or pool "
                        "them on purpose with --pool-protocols (`make figures POOL=1`)", facts.name)
    return {"study": facts.name, "analysis": analysis, "response_kind": facts.kind.name, "protocol_sha256": hashes,
            "protocols_pooled": len(hashes) > 1, "study_folder": facts.folder,
            "study_protocol_versions": list(facts.folder_protocol_sha256), "observers": list(facts.observers)}


def require_kind(facts, kind: str, script: str) -> None:
    """A UserError when the study's responses are of another kind (psyop.protocol.kinds) than this script analyses."""
    if facts.kind.name != kind:
        from psyop.errors import UserError

        raise UserError(f"study {facts.name!r} has {facts.kind.name} responses; {script} analyses {kind} studies "
                        "(`python -m psyop studies DATA` lists each study's kind and its scripts)", facts.name)


def require_columns(trials: pd.DataFrame, columns: list[str], where: str, fix: str) -> None:
    """A UserError naming the missing columns and ``fix``."""
    missing = [c for c in columns if c not in trials]
    if missing:
        from psyop.errors import UserError

        raise UserError(f"no column {', '.join(map(repr, missing))} (columns: {', '.join(map(str, trials.columns))}); "
                        f"{fix}", where)


def run(main: Callable[[], int]) -> int:
    """Run a script's ``main``; bad input (a UserError) or an I/O error (disk full) is one line on
    stderr and exit code 2, not a traceback."""
    from psyop.errors import UserError

    try:
        return main()
    except UserError as error:
        print(f"{Path(sys.argv[0]).name}: error: {error}", file=sys.stderr)
        return error.exit_code
    except OSError as exc:  # disk full, I/O error: one line naming the file and the fix
        from psyop.atomic import io_error

        error = io_error(exc)
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
    return write_text(path, json.dumps(_clean(payload), indent=2) + "\n")


def write_text(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically (psyop.atomic: whole or absent); creates the directory."""
    from psyop.atomic import write_atomic

    return write_atomic(path, text)


def write_csv(table: pd.DataFrame, path: Path) -> Path:
    """Write ``table`` as CSV (no index) atomically; creates the directory."""
    return write_text(path, table.to_csv(index=False))


def read_fits(path: Path, *, data: Path | None = None, study: str | None = None,
              fit_args: tuple[str, ...] = (), rebuild: Callable[[list[str]], int] | None = None) -> pd.DataFrame:
    """Read a psychometric fit cache (results/<study>_fits.csv): ``flags`` '' when none, ``status`` required.

    A cache that cannot be read (empty, truncated, not CSV, an older layout) is only a cache: with
    ``data``, ``study`` and ``rebuild`` (the caller passes analysis/fit_psychometric.py's ``main``, so this
    module does not import its sibling script) it is rebuilt (one line on stderr says so; ``fit_args``: more
    of its arguments), otherwise it is a UserError naming it."""
    from psyop.errors import UserError

    try:
        return _parse_fits(path)
    except UserError as problem:
        if data is None or study is None or rebuild is None:
            raise
        print(f"{Path(sys.argv[0]).name}: {problem}; rebuilding it", file=sys.stderr)
    status = rebuild(["--study", study, "--data", str(data), "--out", str(path), *fit_args])
    if status:
        raise UserError(f"could not rebuild the fit cache (exit {status})", str(path))
    return _parse_fits(path)


def _parse_fits(path: Path) -> pd.DataFrame:
    from psyop.errors import UserError

    try:
        fits = pd.read_csv(path, dtype={"participant": str, "flags": str, "status": str}, keep_default_na=False,
                           na_values=[""])
    except FileNotFoundError:
        raise UserError("no fit cache here; run analysis/fit_psychometric.py --study <study> first (or give --fits, or make figures)", str(path)) from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError) as exc:
        raise UserError(f"fit cache cannot be read ({type(exc).__name__}: {str(exc)[:120]})", str(path)) from None
    if "status" not in fits or "flags" not in fits or "participant" not in fits:
        raise UserError("fit cache lacks the 'participant', 'flags' or 'status' column (half-written, or written "
                        "by an older psyop)", str(path))
    with open(path, "rb") as handle:  # a CSV written whole ends with a newline; a torn one rarely does
        handle.seek(max(0, os.path.getsize(path) - 1))
        torn = handle.read(1) != b"\n"
    if torn or fits["status"].isna().any() or fits["participant"].isna().any():
        raise UserError("fit cache is half-written (a row without participant or status, or no final newline)",
                        str(path))
    fits["flags"] = fits["flags"].fillna("").astype(str)
    return fits
