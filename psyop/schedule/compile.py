"""Protocol + seed -> trial schedule (one row per trial, in execution order).

Deterministic: the same protocol and seed give the same table on every machine (NumPy's
PCG64 streams are stable across platforms). Everything random about a trial that is not drawn
while it runs (order, interval order, near side, fixation start and direction, border phase) is
decided here and written to the table, so a schedule can be inspected and re-run exactly.
Columns are described in docs/architecture.md ("the trial table") and docs/protocols.md.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from psyop.errors import UserError
from psyop.protocol.conditions import condition_label, expand_conditions
from psyop.protocol.model import Protocol
from psyop.protocol.kinds import kind_of
from psyop.protocol.kinds.confidence import confidence_columns
from psyop.protocol.kinds.base import ScheduleInput
from psyop.protocol.scene import FixationTarget, SinusoidalBorder
from psyop.schedule.counterbalance import latin_square_order
from psyop.schedule.counts import expected_duration_s, trial_count  # noqa: F401 - re-exported
from psyop.records import JsonObject

#: Independent random streams derived from the user's seed (adding a stream never changes others).
_STREAM_ORDER, _STREAM_SEEDS, _STREAM_COUNTERBALANCE, _STREAM_STIMULUS, _STREAM_PRACTICE, _STREAM_KIND = range(6)


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, stream])))


def check_seed(seed: object) -> int:
    """A schedule seed must be a non-negative integer."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UserError(f"the seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _balanced_binary(cond_index: np.ndarray, rep_index: np.ndarray, n_conditions: int, repetitions: int,
                     rng: np.random.Generator) -> np.ndarray:
    """0/1 per trial, balanced within each condition: floor(R/2) of each, and for odd R one extra
    of a seeded random value; the positions within a condition are shuffled."""
    half = repetitions // 2
    table = np.zeros((n_conditions, repetitions), dtype=np.int8)
    table[:, half:2 * half] = 1
    if repetitions % 2:
        table[:, -1] = rng.integers(0, 2, size=n_conditions, dtype=np.int8)
    table = rng.permuted(table, axis=1)
    return table[cond_index, rep_index]


def _order(protocol: Protocol, conditions: list[JsonObject], cond_index: np.ndarray, rep_index: np.ndarray,
           rng: np.random.Generator, participant_index: int | None) -> tuple[np.ndarray, np.ndarray]:
    """(permutation of the main trials, block number of each trial in the new order)."""
    randomisation = protocol.design.randomisation
    n = cond_index.size
    if randomisation.kind == "full":
        return rng.permutation(n), np.zeros(n, dtype=np.int64)
    if randomisation.kind == "sequential":
        order = np.lexsort((cond_index, rep_index))  # all conditions once, then again
        return order, np.zeros(n, dtype=np.int64)
    keys: dict[tuple[object, ...], int] = {}
    block_of_condition = np.empty(len(conditions), dtype=np.int64)
    for index, condition in enumerate(conditions):
        key = tuple(condition[name] for name in randomisation.by)
        block_of_condition[index] = keys.setdefault(key, len(keys))
    if randomisation.block_order == "fixed":
        rank = np.arange(len(keys))
    elif randomisation.block_order == "latin_square":
        if participant_index is None:
            raise UserError("block_order: latin_square orders blocks by participant: give the participant index "
                            "(--participant-index N; psyop run also takes it from a participant ID ending in its number, e.g. S07)",
                            "design.randomisation.block_order")
        rank = np.argsort(latin_square_order(len(keys), participant_index))
    else:
        rank = rng.permutation(len(keys))
    block = rank[block_of_condition[cond_index]]
    order = np.lexsort((rng.random(n), block))
    return order, block[order]


def _column(values: list[float | str]) -> np.ndarray:
    if all(isinstance(v, str) for v in values):
        return np.array(values, dtype=object)
    return np.array([float(v) for v in values], dtype=np.float64)


def compile_schedule(protocol: Protocol, seed: int, participant_index: int | None = None) -> pd.DataFrame:
    """The trial table for one participant session of ``protocol``, drawn with ``seed``.

    ``participant_index`` keys the block order of ``block_order: latin_square`` (a Williams design,
    psyop.schedule.counterbalance); other designs ignore it. Blocks are numbered in run order."""
    seed = check_seed(seed)
    design = protocol.design
    conditions = expand_conditions(design)
    n_conditions, repetitions = len(conditions), design.repetitions
    cond_main = np.repeat(np.arange(n_conditions), repetitions)
    rep_main = np.tile(np.arange(repetitions), n_conditions)

    order, block_main = _order(protocol, conditions, cond_main, rep_main, _rng(seed, _STREAM_ORDER),
                               participant_index)
    counterbalance_rng = _rng(seed, _STREAM_COUNTERBALANCE)
    if protocol.response.counterbalance == "balanced":  # the binary choice: order, side or pair order
        binary_main = _balanced_binary(cond_main, rep_main, n_conditions, repetitions, counterbalance_rng)
    else:  # an independent fair coin per trial
        binary_main = counterbalance_rng.integers(0, 2, size=cond_main.size, dtype=np.int8)
    cond_main, binary_main = cond_main[order], binary_main[order]

    n_practice = design.practice_trials
    practice_rng = _rng(seed, _STREAM_PRACTICE)
    cond_practice = practice_rng.integers(0, n_conditions, size=n_practice)
    binary_practice = practice_rng.integers(0, 2, size=n_practice).astype(np.int8)

    cond_index = np.concatenate([cond_practice, cond_main])
    binary = np.concatenate([binary_practice, binary_main]).astype(bool)
    n = cond_index.size
    block = np.concatenate([np.full(n_practice, -1, dtype=np.int64), block_main])

    labels = np.array([condition_label(c, design) for c in conditions], dtype=object)
    columns: dict[str, np.ndarray] = {
        "trial": np.arange(n, dtype=np.int64),
        "block": block,
        "condition": labels[cond_index],
        "trial_seed": _rng(seed, _STREAM_SEEDS).integers(0, 2**63 - 1, size=n, dtype=np.int64),
        "practice": np.arange(n) < n_practice,
    }
    for name in design.factors:
        columns[name] = _column([c[name] for c in conditions])[cond_index]
    if any(f.adaptive is not None for f in design.factors.values()):
        columns["adaptive"] = np.ones(n, dtype=bool)

    kind_input = ScheduleInput(protocol, columns, binary, cond_index, columns["practice"], _rng(seed, _STREAM_KIND))
    columns.update(kind_of(protocol.response).columns(protocol.response, kind_input))
    columns.update(confidence_columns(protocol.response.confidence, kind_input.n))  # the confidence's log columns
    columns.update(_stimulus_columns(protocol, n, _rng(seed, _STREAM_STIMULUS)))
    return pd.DataFrame(columns)


def _stimulus_columns(protocol: Protocol, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for item in protocol.scene:
        if isinstance(item, FixationTarget) and item.path is not None:
            path = item.path
            start = rng.uniform(0.0, 360.0, size=n) if path.start == "random" else np.full(n, float(path.start))
            if path.direction == "random":
                direction = np.where(rng.integers(0, 2, size=n) == 1, 1, -1)
            else:
                direction = np.full(n, 1 if path.direction == "counterclockwise" else -1)
            out[f"{item.id}_start_deg"] = start
            out[f"{item.id}_direction"] = direction.astype(np.int64)
        elif isinstance(item, SinusoidalBorder):
            phase = rng.uniform(0.0, 360.0, size=n) if item.phase == "random" else np.full(n, float(item.phase))
            out[f"{item.id}_phase_deg"] = phase
    return out
