"""Block orders counterbalanced across participants: Williams Latin squares.

A Williams design orders ``k`` blocks so that, over one cycle of participants, every block takes
every position equally often and every block follows every other block equally often (balanced for
first-order carry-over). For even ``k`` the cycle is ``k`` participants; for odd ``k`` it is ``2k``
(the square and its mirror). Participant ``i`` gets row ``i mod cycle``: the order is keyed to the
participant index, not drawn from the seed, so a lab running participants 0..2k-1 gets a balanced set.
"""

from __future__ import annotations

import re

from psyop.errors import UserError


def williams_rows(k: int) -> list[list[int]]:
    """Every row of the Williams design for ``k`` blocks (``k`` rows for even ``k``, ``2k`` for odd).

    Examples
    --------
    >>> williams_rows(4)
    [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    >>> len(williams_rows(3))
    6
    """
    if k < 1:
        raise ValueError("a Latin square needs at least one block")
    first = [0]
    low, high = 1, k - 1
    take_low = True
    while len(first) < k:
        first.append(low if take_low else high)
        if take_low:
            low += 1
        else:
            high -= 1
        take_low = not take_low
    rows = [[(b + i) % k for b in first] for i in range(k)]
    if k % 2:
        rows += [list(reversed(r)) for r in rows]
    return rows


def latin_square_order(k: int, participant_index: int) -> list[int]:
    """The block order (block ranks in run order) of participant ``participant_index``.

    Examples
    --------
    >>> latin_square_order(4, 5)
    [1, 2, 0, 3]
    """
    if participant_index < 0:
        raise UserError(f"participant index {participant_index} is negative; give 0 or more", "--participant-index")
    rows = williams_rows(k)
    return rows[participant_index % len(rows)]


_TRAILING_DIGITS = re.compile(r"(\d+)$")


def participant_index_from_id(participant: str) -> int | None:
    """The number a participant ID ends in (``S07`` -> 7, ``P012`` -> 12), or None.

    Examples
    --------
    >>> participant_index_from_id("S07"), participant_index_from_id("pilot")
    (7, None)
    """
    match = _TRAILING_DIGITS.search(participant)
    return int(match.group(1)) if match else None


def resolve_participant_index(requested: int | None, participant: str, recorded: int | None,
                              location: str = "--participant-index") -> int | None:
    """The participant index a session uses: ``requested`` (``--participant-index``), else the number the
    participant ID ends in, else None; a resumed session keeps its ``recorded`` index (a different
    ``requested`` one is a UserError: the block order would change mid-session).

    Examples
    --------
    >>> resolve_participant_index(None, "S03", None), resolve_participant_index(5, "S03", None)
    (3, 5)
    """
    if requested is not None and requested < 0:
        raise UserError(f"participant index {requested} is negative; give 0 or more", location)
    if recorded is not None:
        if requested is not None and requested != recorded:
            raise UserError(f"cannot resume: participant index differs from the existing session ({recorded} there, "
                            f"{requested} now); drop --participant-index to resume it", location)
        return recorded
    return requested if requested is not None else participant_index_from_id(participant)


def block_sequence(schedule, by: list[str]) -> list[dict]:
    """The blocks of a blocked schedule in run order: each block's ``by`` factor values (practice left out)."""
    main = schedule[schedule["block"] >= 0]
    return [{name: (v.item() if hasattr(v, "item") else v) for name, v in zip(by, row)}
            for row in main.groupby("block", sort=True)[by].first().itertuples(index=False)]
