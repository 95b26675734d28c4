"""`psyop --help` and `psyop validate` import only what they use (issue 13: every sub-command
imported pandas and pydantic; `psyop --help` took 2.6 s). Time itself is measured in
benchmarks/bench_cli_startup.py; this checks which modules get imported."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
HEAVY = ["pandas", "pyarrow", "pydantic", "numpy", "scipy", "matplotlib", "moderngl", "zmq", "tqdm", "yaml"]


def imported_by(*argv: str) -> set[str]:
    code = ("import json, sys\nfrom psyop.cli import main\n"
            "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            f"print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]), file=sys.stderr)")
    result = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=REPO,
                            env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=120)
    return set(json.loads(result.stderr.strip().splitlines()[-1]))


def test_help_imports_no_heavy_library() -> None:
    assert imported_by("--help") == set()
    assert imported_by("run", "--help") == set()


def test_validate_imports_the_protocol_model_but_not_pandas_or_rendering() -> None:
    loaded = imported_by("validate", str(REPO / "protocols" / "detection.yaml"))
    assert {"pydantic", "yaml"} <= loaded
    assert not loaded & {"pandas", "pyarrow", "scipy", "matplotlib", "moderngl", "zmq", "tqdm"}
