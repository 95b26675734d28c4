"""The number of participants a target power needs (``psyop power --target-power``).

The search over n is stated, not tuned: power is evaluated (``run_power``, the stated
``--replications`` per n, the same per-replication seeds as any power run) at the bracketing
sequence ``min, 2 min, 4 min, ...`` capped at ``max`` (``max`` always included), stopping early once
every test's lower Clopper-Pearson bound reaches the target. Then, per test and per criterion (the
upper bound, the point estimate, the lower bound reaching the target), integers are bisected between
the last bracket point that fails and the first that passes. Each n is simulated once and shared by
all tests and criteria; the bisections of one round are run together.

A bisection ends at a crossing: the criterion holds at n and fails at n - 1 (both simulated). That is
the smallest such n if power grows with n; with noisy estimates a smaller n may pass by chance, which
the search does not look for. ``n`` (point estimate) comes with its interval ``[n_ci_high, n_ci_low]``:
the n whose upper bound reaches the target and the n whose lower bound does. A criterion that fails
at every n up to ``max`` has no number, only a flag naming the test and the largest n tried; one
that already holds at ``min`` is flagged as such (smaller n were not tried).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import pandas as pd

from psyop.errors import UserError
from psyop.power.run import PowerRun, run_power

#: (target-table column, power-table column it bisects on, what it says)
CRITERIA = (("n_ci_high", "ci_high", "upper 95 % bound"), ("n", "power", "power estimate"),
            ("n_ci_low", "ci_low", "lower 95 % bound"))
TARGET_COLUMNS = ["test", "target_power", "n", "n_ci_high", "n_ci_low", "power", "ci_low", "ci_high",
                  "power_below", "n_replications", "min_participants", "max_participants", "flag"]

#: evaluates power at the given participant counts: the rows of power_table for them
Evaluate = Callable[[PowerRun, tuple[int, ...]], pd.DataFrame]


@dataclass(frozen=True)
class TargetSearch:
    target_power: float
    min_participants: int = 2
    max_participants: int = 40

    def __post_init__(self) -> None:
        if not 0 < self.target_power < 1:
            raise UserError(f"--target-power must be in (0, 1), got {self.target_power:g}", "--target-power")
        if self.min_participants < 2:
            raise UserError(f"--min-participants must be >= 2, got {self.min_participants}", "--min-participants")
        if self.max_participants < self.min_participants:
            raise UserError(f"--max-participants ({self.max_participants}) must be >= --min-participants "
                            f"({self.min_participants})", "--max-participants")


@dataclass
class _Bisection:
    """One test's search for one criterion: ``passes(hi)``; ``lo`` fails (None: hi is the minimum)."""

    test: str
    column: str
    lo: int | None
    hi: int

    @property
    def mid(self) -> int | None:
        return None if self.lo is None or self.hi - self.lo <= 1 else (self.lo + self.hi) // 2


def bracket(search: TargetSearch) -> list[int]:
    """``min, 2 min, 4 min, ...`` below ``max``, then ``max``."""
    points, n = [], search.min_participants
    while n < search.max_participants:
        points.append(n)
        n *= 2
    return points + [search.max_participants]


def evaluate_power(run: PowerRun, participants: tuple[int, ...]) -> pd.DataFrame:
    """The power table of ``run`` at ``participants`` (the real replications, checkpointed as any run)."""
    table, _ = run_power(replace(run, participants=participants))
    return table


def _value(table: pd.DataFrame, test: str, n: int, column: str) -> float:
    rows = table[(table["test"] == test) & (table["participants"] == n)]
    return float(rows[column].iloc[0]) if len(rows) else float("nan")


def _passes(table: pd.DataFrame, search: TargetSearch, test: str, n: int, column: str) -> bool:
    return _value(table, test, n, column) >= search.target_power  # NaN (test absent) fails


def _start(table: pd.DataFrame, search: TargetSearch, test: str, column: str,
           tried: list[int]) -> _Bisection | None:
    """The bisection between the last bracket point failing and the first passing; None: none passes."""
    for i, n in enumerate(tried):
        if _passes(table, search, test, n, column):
            return _Bisection(test, column, tried[i - 1] if i else None, n)
    return None


def _run_brackets(run: PowerRun, search: TargetSearch, evaluate: Evaluate) -> tuple[pd.DataFrame, list[int]]:
    """Power at the bracket points, until every test's lower bound reaches the target or at ``max``."""
    tables: list[pd.DataFrame] = []
    tried: list[int] = []
    for n in bracket(search):
        tables.append(evaluate(run, (n,)))
        tried.append(n)
        at_n = tables[-1]
        if len(at_n) and bool((at_n["ci_low"] >= search.target_power).all()):
            break
    return pd.concat(tables, ignore_index=True), tried


def search_target(run: PowerRun, search: TargetSearch,
                  evaluate: Evaluate = evaluate_power) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The power table at every n simulated (sorted as power_table sorts) and the target table."""
    table, tried = _run_brackets(run, search, evaluate)
    tests = list(dict.fromkeys(table["test"]))
    found = {(test, column): _start(table, search, test, column, tried)
             for test in tests for _, column, _ in CRITERIA}
    active = [b for b in found.values() if b is not None]
    while active:
        done = set(int(n) for n in table["participants"])
        need = tuple(sorted({m for b in active if (m := b.mid) is not None and m not in done}))
        if need:
            table = pd.concat([table, evaluate(run, need)], ignore_index=True)
        for b in active:
            if (m := b.mid) is not None:
                if _passes(table, search, b.test, m, b.column):
                    b.hi = m
                else:
                    b.lo = m
        active = [b for b in active if b.mid is not None]
    table = _sorted(table, tests)
    return table, target_table(table, search, found, max(tried))


def _sorted(table: pd.DataFrame, tests: list[str]) -> pd.DataFrame:
    order = {test: i for i, test in enumerate(tests)}
    keys = table["test"].map(order)
    return table.assign(_order=keys).sort_values(["_order", "participants"]).drop(columns="_order") \
        .reset_index(drop=True)


def _flags(search: TargetSearch, test: str, found: dict[tuple[str, str], _Bisection | None],
           largest_tried: int, replications: int) -> str:
    from scipy.stats import binomtest

    flags = []
    for _, column, label in CRITERIA:
        b = found[(test, column)]
        if b is None:
            ceiling = float(binomtest(replications, replications).proportion_ci(method="exact").low)
            why = (f" (with {replications} replications per n the lower bound is at most {ceiling:.3f})"
                   if column == "ci_low" and ceiling < search.target_power else "")
            flags.append(f"{test}: {label} below {search.target_power:g} at every n tried, up to {largest_tried} "
                         f"(--max-participants {search.max_participants}): not reached{why}")
        elif b.lo is None:
            flags.append(f"{label} reaches {search.target_power:g} already at --min-participants "
                         f"{search.min_participants}: smaller n not tried")
    return "; ".join(flags)


def target_table(table: pd.DataFrame, search: TargetSearch, found: dict[tuple[str, str], _Bisection | None],
                 largest_tried: int) -> pd.DataFrame:
    """One row per test: the n of each criterion (empty where not reached, with the flag), and the
    power and interval at ``n`` and the power at ``n - 1``."""
    rows = []
    for test in dict.fromkeys(table["test"]):
        ns = {name: (b.hi if (b := found[(test, column)]) is not None else None) for name, column, _ in CRITERIA}
        n = ns["n"]
        at = {c: (_value(table, test, n, c) if n is not None else float("nan"))
              for c in ("power", "ci_low", "ci_high", "n_replications")}
        below = _value(table, test, n - 1, "power") if n is not None else float("nan")
        rows.append({"test": test, "target_power": search.target_power, **ns, **at, "power_below": below,
                     "min_participants": search.min_participants, "max_participants": search.max_participants,
                     "flag": _flags(search, test, found, largest_tried, int(table["n_replications"].max()))})
    out = pd.DataFrame(rows, columns=TARGET_COLUMNS)
    for column in ("n", "n_ci_high", "n_ci_low", "n_replications"):
        out[column] = out[column].astype("Int64")
    return out


def format_target(target: pd.DataFrame) -> str:
    """The target table for the terminal (and power.txt)."""
    lines = [f"{'test':<48} {'target':>6} {'N':>4}  N interval (upper .. lower bound)  power at N [95% CI]"
             "  at N-1  flag"]
    for _, r in target.iterrows():
        def cell(name: str) -> str:
            return "-" if pd.isna(r[name]) else str(int(r[name]))
        at_n = "-" if pd.isna(r["n"]) else f"{r['power']:.3f} [{r['ci_low']:.3f}, {r['ci_high']:.3f}]"
        below = "-" if pd.isna(r["power_below"]) else f"{r['power_below']:.3f}"
        lines.append(f"{r['test']:<48} {r['target_power']:>6g} {cell('n'):>4}  "
                     f"{cell('n_ci_high'):>6} .. {cell('n_ci_low'):<26}  {at_n:<20}  {below:>6}  {r['flag']}")
    return "\n".join(lines)
