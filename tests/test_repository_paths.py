"""The repository names only paths relative to itself (../shared) or given by the environment:
`.ci/run` looked for the OpenXR test runtime's build script at an absolute /work/shared/openxr, and
then for the runtime itself at the build script's cache folder under /var/cache; the headset tests,
the OpenXR benchmark and the docs' example commands named such folders too."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: an absolute path into a folder outside the checkout: this workplace's, a home, a system cache or
#: scratch folder (/dev/null, /usr/bin/env and /proc/self are the system's, not places to keep files)
ABSOLUTE = re.compile(r"(?<![\w.~/$}-])/(work|home|root|var|tmp|opt|srv|mnt|media|scratch)/")
#: lines that name such a path on purpose: hostile input a test feeds psyop, or an assertion of absence
ALLOWED = {
    "tests/analysis/test_analysis_study_scripts.py": ('"/work/" not in text',),
}
#: this file names them to describe and find them
SELF = "tests/test_repository_paths.py"


def _tracked(*paths: str) -> list[str]:
    return subprocess.run(["git", "ls-files", *paths], cwd=REPO, capture_output=True, text=True,
                          check=True).stdout.split()


def test_no_absolute_paths_outside_the_repository() -> None:
    files = _tracked(".ci", "Makefile", "figures.mk", "pyproject.toml", "psyop", "analysis", "benchmarks",
                     "protocols", "assets", "docs", "README.md", "tests")
    assert ".ci/run" in files and "tests/devices/xr/monado.py" in files
    found = []
    for name in files:
        if name == SELF:
            continue
        path = REPO / name
        try:
            text = path.read_text(encoding="utf-8")
        except (UnicodeDecodeError, OSError):
            continue  # binary assets
        for i, line in enumerate(text.splitlines(), 1):
            if ABSOLUTE.search(line) and not any(ok in line for ok in ALLOWED.get(name, ())):
                found.append(f"{name}:{i}: {line.strip()}")
    assert not found, "absolute paths outside the repository:\n" + "\n".join(found)


def test_ci_finds_the_runtime_the_build_script_installs(tmp_path: Path) -> None:
    """.ci/run takes the install prefix from PSYOP_MONADO_PREFIX or the build script's own default: with a
    stand-in build script (a checkout whose ../shared/openxr holds it) it builds into that prefix and
    exports the manifest there, naming no folder itself. `make test` is replaced by a stand-in too."""
    clone = tmp_path / "repo"
    (clone / ".ci").mkdir(parents=True)
    (clone / ".ci" / "run").write_text((REPO / ".ci" / "run").read_text())
    (clone / "Makefile").write_text("test:\n\t@echo \"XR_RUNTIME_JSON=$$XR_RUNTIME_JSON\"\n")
    prefix = tmp_path / "cache" / "install"
    shared = tmp_path / "shared" / "openxr"
    shared.mkdir(parents=True)
    (shared / "build-monado.sh").write_text(
        'PREFIX="${2:-${PSYOP_MONADO_PREFIX:-' + str(prefix) + '}}"\n'
        'mkdir -p "$PREFIX/share/openxr/1" && echo {} > "$PREFIX/share/openxr/1/openxr_monado.json"\n'
        'echo "built in $PREFIX"\n')
    env = {k: v for k, v in os.environ.items() if k not in ("XR_RUNTIME_JSON", "PSYOP_MONADO_PREFIX",
                                                             "PSYOP_OPENXR_DIR", "MAKEFLAGS", "MAKELEVEL")}
    done = subprocess.run(["bash", ".ci/run"], cwd=clone, capture_output=True, text=True, env=env, timeout=60)
    manifest = prefix / "share" / "openxr" / "1" / "openxr_monado.json"
    if os.getuid() == 0:  # a root CI builds; a non-root one uses only a cached build
        assert done.returncode == 0, done.stdout + done.stderr
        assert f"XR_RUNTIME_JSON={manifest}" in done.stdout, done.stdout
    other = tmp_path / "given"
    done = subprocess.run(["bash", ".ci/run"], cwd=clone, capture_output=True, text=True, timeout=60,
                          env=dict(env, PSYOP_MONADO_PREFIX=str(other)))
    if os.getuid() == 0:
        assert done.returncode == 0 and f"XR_RUNTIME_JSON={other / 'share/openxr/1/openxr_monado.json'}" \
            in done.stdout, done.stdout + done.stderr
