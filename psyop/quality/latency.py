"""The gaze-to-photon latency of a study's sessions the way a methods section states it (psyop.session.latency:
what the number includes). Reads each session's frames.parquet, trials.parquet and session.json; changes
nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from psyop import datacontract as dc
from psyop.session.log.record import read_record_file
from psyop.session.latency import TRIAL_KIND, GazeLatency, age_stats, frame_gaze_ages
from psyop.session.timing import _recorded_phase


def latency_sentence(session_dirs: list[Path]) -> str:
    """Median, 95th percentile and maximum gaze-to-photon age of every session's interval frames with valid gaze,
    the latency added on purpose (if any), and the trials over the protocol's bound (``gaze_age_ok`` false);
    '' when no session logged the age."""
    ages: list[np.ndarray] = []
    intrinsic: list[np.ndarray] = []
    added: set[float] = set()
    n_trials = n_late = n_sessions = 0
    rule = GazeLatency()
    for directory in session_dirs:
        frames_file = Path(directory) / dc.FRAMES_FILE
        meta_file = Path(directory) / dc.SESSION_METADATA_FILE
        if not frames_file.is_file() or not meta_file.is_file():
            continue
        frames = pd.read_parquet(frames_file)
        if "gaze_age_at_display_s" not in frames or not len(frames):
            continue
        record = read_record_file(meta_file)
        phases = [_recorded_phase(p) for p in record.phases] if record is not None else []
        rule = GazeLatency.of_record(record.gaze_latency if record is not None else None)
        interval = frames[[kind == TRIAL_KIND for kind, _ in _kinds(frames, phases)]] if len(frames) else frames
        ages.append(np.asarray([a for _, a in frame_gaze_ages(interval, phases)], dtype=np.float64))
        if "gaze_age_intrinsic_s" in interval:
            keep = interval["gaze_valid"].fillna(False).to_numpy(dtype=bool)
            intrinsic.append(interval["gaze_age_intrinsic_s"].to_numpy(dtype=np.float64, na_value=np.nan)[keep])
        if "added_latency_s" in frames:
            added |= {round(float(a) * 1e3, 6) for a in frames["added_latency_s"].dropna()}
        trials = pd.read_parquet(Path(directory) / dc.TRIALS_FILE)
        n_trials += len(trials)
        n_late += int(dc.late_gaze_mask(trials).sum())
        n_sessions += 1
    stats = age_stats(np.concatenate(ages) if ages else np.zeros(0))
    if not stats["n_frames"]:
        return ""
    text = (f"Gaze-to-photon latency (display time minus the time of the gaze sample each frame was rendered with, "
            f"interval frames with valid gaze; the display's own latency is included only where the display time is "
            f"a predicted photon time, as a headset runtime gives): median {stats['median_s'] * 1e3:.1f} ms, 95th "
            f"percentile {stats['p95_s'] * 1e3:.1f} ms, maximum {stats['max_s'] * 1e3:.1f} ms over "
            f"{stats['n_frames']} frames in {n_sessions} sessions")
    if any(added):
        own = age_stats(np.concatenate(intrinsic) if intrinsic else np.zeros(0))
        text += (f"; latency added on purpose: {', '.join(f'{a:g}' for a in sorted(added))} ms (held past samples), "
                 f"the system's own median {(own['median_s'] or float('nan')) * 1e3:.1f} ms")
    if rule.max_age_s is None:
        return text + "; the protocol states no bound (trial.max_gaze_age_ms)."
    return text + (f"; {n_late} of {n_trials} trials had more than {rule.max_over_share:.0%} of their interval frames "
                   f"over the protocol's bound of {rule.max_age_s * 1e3:g} ms (not counting added latency; "
                   "gaze_age_ok false).")


def _kinds(frames: pd.DataFrame, phases: list) -> list[tuple[str, int]]:
    kind_of = {p.name: p.show for p in phases}
    return [(kind_of.get(str(n), "response"), i) for i, n in enumerate(frames["phase"])]
