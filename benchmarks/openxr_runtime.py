"""Where ../shared/openxr/build-monado.sh installs the OpenXR test runtime (Monado), for the headset
benchmark and the headset tests alike (tests/devices/xr/monado.py imports it from here)."""

from __future__ import annotations

import os
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: the manifest below the build script's install prefix
MANIFEST = Path("share") / "openxr" / "1" / "openxr_monado.json"
#: what a caller prints when neither the variable nor the build script says where the runtime is
NO_RUNTIME = "(no PSYOP_MONADO_PREFIX, no ../shared/openxr/build-monado.sh)"


def default_runtime_json() -> str | None:
    """The runtime manifest the build script installs: below PSYOP_MONADO_PREFIX, else below the default
    prefix the script itself names (``${PSYOP_MONADO_PREFIX:-...}``), read from ../shared/openxr/build-monado.sh
    (or PSYOP_OPENXR_DIR's): the repository names no path outside itself. None without either."""
    prefix = os.environ.get("PSYOP_MONADO_PREFIX")
    if not prefix:
        folder = Path(os.environ.get("PSYOP_OPENXR_DIR") or REPO.parent / "shared" / "openxr")
        try:
            match = re.search(r"PSYOP_MONADO_PREFIX:-([^}]*)}", (folder / "build-monado.sh").read_text())
        except OSError:
            return None
        prefix = match.group(1) if match else None
    return str(Path(prefix) / MANIFEST) if prefix else None
