"""block_order: latin_square: a Williams design keyed to the participant index (issue 18: labs need
block orders balanced across participants; `random` is drawn per seed, `fixed` is one order for all)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from itertools import permutations
from pathlib import Path

import pytest

from psyop.errors import UserError
from psyop.protocol import parse_protocol
from psyop.schedule import compile_schedule
from psyop.schedule.counterbalance import williams_rows

REPO = Path(__file__).resolve().parents[2]
DETECTION = (REPO / "protocols" / "detection.yaml").read_text()


def _blocked(levels: list[float]) -> str:
    text = DETECTION.replace("randomisation: {kind: full}",
                             "randomisation: {kind: blocked, by: [back_D], block_order: latin_square}")
    return text.replace("levels: [1, 2, 3]  ", f"levels: {levels}  ").replace("repetitions: 15 ", "repetitions: 1 ")


@pytest.mark.parametrize("k", [2, 3, 4, 5, 6])
def test_orders_over_2k_participants_are_balanced_for_position_and_carry_over(k: int) -> None:
    """Over 2k participants, as the schedule gives them (not the square alone): every block in every
    position equally often, and every ordered pair of different blocks adjacent equally often."""
    levels = [float(1 + 0.5 * i) for i in range(k)]
    protocol = parse_protocol(_blocked(levels), "latin.yaml")
    position, carry = Counter(), Counter()
    for participant in range(2 * k):
        schedule = compile_schedule(protocol, seed=1000 + participant, participant_index=participant)
        order = schedule[schedule["block"] >= 0].groupby("block")["back_D"].first().tolist()
        assert sorted(order) == levels  # each block once
        position.update(enumerate(order))
        carry.update(zip(order, order[1:]))
    assert set(position.values()) == {2}  # 2k participants, k positions: each block twice per position
    pairs = list(permutations(levels, 2))
    assert set(carry) == set(pairs)
    assert len({carry[p] for p in pairs}) == 1, carry  # first-order carry-over balanced


def test_order_is_keyed_to_the_participant_not_the_seed() -> None:
    protocol = parse_protocol(_blocked([1, 2, 3, 4]), "latin.yaml")
    first = [compile_schedule(protocol, seed=s, participant_index=2).groupby("block")["back_D"].first().tolist()
             for s in range(5)]
    assert all(order == first[0] for order in first)
    assert first[0] == [1 + b for b in williams_rows(4)[2]]
    with pytest.raises(UserError, match="participant index"):
        compile_schedule(protocol, seed=1)


def test_latin_square_outside_a_blocked_design_is_refused_with_its_location() -> None:
    text = DETECTION.replace("randomisation: {kind: full}", "randomisation: {kind: full, block_order: latin_square}")
    with pytest.raises(UserError) as info:
        parse_protocol(text, "x.yaml")
    assert "only applies to kind: blocked" in str(info.value) and info.value.location.startswith("x.yaml:")


def test_show_prints_each_participants_order_and_a_session_records_it(tmp_path: Path) -> None:
    path = tmp_path / "latin.yaml"
    path.write_text(_blocked([1, 2, 3, 4]).replace("levels: [0, 0.25, 0.5, 0.75, 1]", "levels: [0, 1]"))
    shown = subprocess.run([sys.executable, "-m", "psyop", "show", str(path), "--participants", "5"],
                           capture_output=True, text=True, cwd=REPO)
    assert shown.returncode == 0, shown.stderr
    lines = [line.strip() for line in shown.stdout.splitlines() if line.strip().startswith("S0")]
    assert len(lines) == 5
    expected = [" -> ".join(f"back_D={1 + b}" for b in williams_rows(4)[i % 4]) for i in range(1, 6)]
    assert [line.split(": ", 1)[1] for line in lines] == expected
    run = subprocess.run([sys.executable, "-m", "psyop", "run", str(path), "--participant", "S03", "--data",
                          str(tmp_path / "data"), "--render", "cameras", "--no-progress"],
                         capture_output=True, text=True, cwd=REPO)
    assert run.returncode == 0, run.stderr
    meta = json.loads((tmp_path / "data" / "detection" / "sub-S03" / "ses-1" / "session.json").read_text())
    assert meta["participant_index"] == 3
    assert meta["block_order"]["kind"] == "latin_square"
    assert [b["back_D"] for b in meta["block_order"]["blocks"]] == [1 + b for b in williams_rows(4)[3]]
