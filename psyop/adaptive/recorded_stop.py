"""The adaptive stop record of a logged session, rebuilt from its recorded protocol and its log.

`psyop recover` uses it: session.json's ``adaptive_stop`` is rewritten each time a condition
stops, right after that trial is durable, so a session killed in between has a stale record.
The stop decision is a function of the protocol, the seed and the logged trials only, so the
record is rebuilt here exactly as the session would have written it.
"""

from __future__ import annotations


import pandas as pd

from psyop.adaptive.session import AdaptiveLevels, adaptive_plan
from psyop.errors import UserError
from psyop.records import JsonMapping, JsonObject


def rebuilt_stop_record(meta: JsonMapping, trials: pd.DataFrame | None) -> JsonObject | None:
    """``adaptive_stop`` for a session's metadata and logged trials; None when the session has no
    adaptive levels, or its metadata lacks the protocol text or seed, or that text no longer
    validates here (then the recorded one stands)."""
    from psyop.protocol import parse_protocol
    from psyop.schedule import compile_schedule

    text, seed = meta.get("protocol_text"), meta.get("seed")
    if not meta.get("adaptive") or not isinstance(text, str) or seed is None:
        return None
    try:
        protocol = parse_protocol(text, str(meta.get("protocol_file") or "<protocol>"))
    except UserError:  # e.g. its textures moved: the recorded record stands (recover stays conservative)
        return None
    plan = adaptive_plan(protocol)
    if plan is None:
        return None
    index = meta.get("participant_index")
    schedule = compile_schedule(protocol, int(seed), participant_index=index if isinstance(index, int) else None)
    logged = trials if trials is not None and len(trials) and "trial" in trials else None
    levels = AdaptiveLevels.from_log(plan, logged)
    recorded = set() if logged is None else {int(t) for t in logged["trial"]}
    return levels.stop_summary(schedule, recorded)
