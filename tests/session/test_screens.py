"""A participant's whole session (issue 40 item 3): the protocol's ``session:`` screens (instructions, breaks,
questionnaires, end screen) run by the loop around the trials, logged in events.parquet and
questionnaires.parquet (finalised and verified like the other session files), drawn on the head-fixed text
panel (mono and stereo) and by ``psyop render``; bad input is one line naming file:line:column, exit 2."""

from __future__ import annotations

import json
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from psyop.cli import main
from psyop.errors import UserError
from psyop.finalised import verify_session
from psyop.protocol import load_protocol, parse_protocol
from psyop.protocol.session_screens import WRAP_CHARS
from psyop.run.runner import SessionOptions, run_session
from psyop.schedule import compile_schedule
from psyop.session.screens import Moment, ScreenRunner, screens_of_kind
from psyop.statistics.questionnaires import load_questionnaires, ssq_scores

REPO = Path(__file__).resolve().parents[2]
SCREENS = """
session:
  instructions:
    pages:
      - text: "Welcome.\\n\\nEach trial shows two pictures of targets in front of a grid."
        expected_s: 12
      - text: Answer which one looked more real. Press a key to start.
        expected_s: 3
  breaks: {every_trials: 2, expected_s: 20}
  questionnaires:
    - {name: ssq, when: [start, end]}
  end_screen: {text: Thank you! The session is over., expected_s: 4}
"""


def _protocol_text(repetitions: int = 2) -> str:
    text = (REPO / "protocols" / "realism.yaml").read_text()
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", rf"\g<1> {repetitions}", text)  # 3 pairs x 2: 6 trials
    return text + SCREENS


@pytest.fixture(scope="module")
def sessions(tmp_path_factory) -> Path:
    """Two simulated participants' headless sessions of the protocol with screens."""
    directory = tmp_path_factory.mktemp("screens")
    path = directory / "realism_screens.yaml"
    path.write_text(_protocol_text())
    for participant in ("S01", "S02"):
        outcome = run_session(load_protocol(path), compile_schedule,
                              SessionOptions(participant=participant, data_root=directory / "data", progress=False,
                                             fsync=False, render="cameras"))
        assert outcome.status == "complete", outcome.message
    return directory


def _session(sessions: Path, participant: str = "S01") -> Path:
    return sessions / "data" / "realism" / f"sub-{participant}" / "ses-1"


def test_events_list_every_screen_in_order_with_its_duration(sessions) -> None:
    events = pd.read_parquet(_session(sessions) / "events.parquet")
    trials = pd.read_parquet(_session(sessions) / "trials.parquet")
    expected = ([("instructions", "start", 0, 12.0), ("instructions", "start", 1, 3.0)]
                + [("questionnaire", "start", i, 4.0) for i in range(16)]
                + [("break", "every_trials", 0, 20.0), ("break", "every_trials", 0, 20.0)]
                + [("questionnaire", "end", i, 4.0) for i in range(16)] + [("end", "end", 0, 4.0)])
    got = list(events[["screen", "when", "page", "duration_s"]].itertuples(index=False, name=None))
    assert got == expected
    assert list(events["seq"]) == list(range(1, len(expected) + 1))
    assert (events["end_s"] - events["start_s"] == events["duration_s"]).all()
    assert (events["start_s"].iloc[1:].to_numpy() >= events["end_s"].iloc[:-1].to_numpy()).all()  # one at a time
    breaks = events[events["screen"] == "break"]
    assert list(breaks["trials_done"]) == [2, 4] and list(breaks["trials_left"]) == [4, 2]
    assert list(breaks["before_trial"]) == [2, 4]
    assert breaks["text"].iloc[0].startswith("2 trials done, 4 left.")
    # the trials run between the screens: the first after the start questionnaire, the break before trial 2
    assert trials["trial_start_s"].min() == events["end_s"].iloc[17]
    assert trials.set_index("trial").loc[2, "trial_start_s"] == breaks["end_s"].iloc[0]
    assert events["end_s"].iloc[-1] >= trials["trial_end_s"].max()
    assert set(events["ended_by"]) == {"simulated"}


def test_questionnaires_have_16_answers_per_ssq_and_scores_differ_between_participants(sessions) -> None:
    answers = pd.read_parquet(_session(sessions) / "questionnaires.parquet")
    per_administration = answers.groupby(["administration", "when"])["item"].agg(list)
    assert list(per_administration.index) == [(1, "start"), (2, "end")]
    assert all(items == list(range(16)) for items in per_administration)
    assert answers["answer"].between(0, 3).all() and (answers["answered_by"] == "simulated").all()
    assert list(answers["item_text"].iloc[:2]) == ["General discomfort", "Fatigue"]
    assert set(answers["answer_label"]) <= {"none", "slight", "moderate", "severe"}
    loaded = load_questionnaires(sessions / "data", "realism")  # each session verified first
    scores = ssq_scores(loaded)
    assert len(scores) == 4 and (scores["n_answered"] == 16).all()
    assert np.isfinite(scores["total"]).all()
    totals = scores.set_index(["participant", "when"])["total"]
    assert totals["S01"].tolist() != totals["S02"].tolist()
    by_participant = loaded.groupby("participant")["answer"].apply(list)
    assert by_participant["S01"] != by_participant["S02"]


def test_screen_files_are_finalised_and_verified(sessions, tmp_path) -> None:
    import shutil

    meta = json.loads((_session(sessions) / "session.json").read_text())
    assert {"events.parquet", "questionnaires.parquet"} <= set(meta["finalised_files"])
    verify_session(_session(sessions))
    copy = tmp_path / "ses-1"
    shutil.copytree(_session(sessions), copy)
    events = pd.read_parquet(copy / "events.parquet")
    events.loc[0, "duration_s"] = 1.0  # an edit: valid parquet, other content
    events.to_parquet(copy / "events.parquet")
    with pytest.raises(UserError, match="events.parquet"):
        verify_session(copy)


def test_a_simulated_participant_is_deterministic(sessions, tmp_path) -> None:
    """The same seed gives the same answers (a rerun of S01 in another folder)."""
    path = sessions / "realism_screens.yaml"
    run_session(load_protocol(path), compile_schedule,
                SessionOptions(participant="S01", data_root=tmp_path, progress=False, fsync=False, render="cameras"))
    again = pd.read_parquet(tmp_path / "realism" / "sub-S01" / "ses-1" / "questionnaires.parquet")
    first = pd.read_parquet(_session(sessions) / "questionnaires.parquet")
    assert again["answer"].tolist() == first["answer"].tolist()


def test_a_live_participant_ends_a_screen_with_an_answer_input() -> None:
    """Live pacing: the screen lasts until the response source gives an input; an input that is a scale point
    is the answer, any other leaves the answer null (recorded in answered_by)."""
    from psyop.session.clock import VirtualClock

    protocol = parse_protocol(_protocol_text(1), "study.yaml")
    assert protocol.session is not None
    inputs = iter([None] * 30 + ["2"] + [None] * 5 + ["left"] + [None, None, "1"] * 14)
    polled: list[float] = []

    def live_input(row, now_s):
        polled.append(now_s)
        return next(inputs)

    class Recorder:
        def __init__(self):
            self.events, self.answers = [], []

        def append_event(self, row):
            self.events.append(dict(row))

        def append_answers(self, rows):
            self.answers += [dict(r) for r in rows]

        def close(self):
            pass

    clock = VirtualClock()
    gaze = SimpleNamespace(set_plan=lambda plan: None, drain_raw=lambda: [], latest=lambda now: None)
    host = SimpleNamespace(identity={"study": "realism", "participant": "L1", "session": 1}, clock=clock, gaze=gaze,
                           renderer=None, display=SimpleNamespace(wait_until_ready=lambda: None),
                           store=SimpleNamespace(run_index=0, keeps_samples=False),
                           config=SimpleNamespace(every_frame=False), frame_period_s=1 / 90, events=())
    recorder = Recorder()
    runner = ScreenRunner(protocol.session, "live", 1, recorder, True, live_input)
    ssq = protocol.session.questionnaires[0]
    runner._administer(host, ssq.model_copy(), Moment("end", -1, 0, 3, 3), {"trial": 2})  # 16 items
    first, second = recorder.answers[:2]
    assert first["answer"] == 2 and first["answer_label"] == "moderate" and first["answered_by"] == "input:2"
    assert second["answer"] is None and second["answered_by"] == "input:left"
    assert recorder.events[0]["duration_s"] == pytest.approx(0.30, abs=0.015)  # 30 polls 10 ms apart
    assert len(recorder.events) == 16 and [a["answer"] for a in recorder.answers[2:]] == [1] * 14


def _screen_text_frames(eyes: str, gl_context):
    """Per screen kind and eye: (the frame of its text, the frame without it) through the session's renderer."""
    from psyop.rendering import Renderer
    from psyop.session.plan import compile_plan
    from psyop.session.scene_renderer import SceneRenderer
    from psyop.stimulus import blank_scene

    text = _protocol_text(1)
    if eyes == "stereo":
        text = text.replace("eyes: right ", "eyes: stereo ", 1)
    plan = compile_plan(parse_protocol(text, str(REPO / "protocols" / "study.yaml")), tracker_ipd_m=0.064)
    assert plan.protocol.session is not None
    renderer = SceneRenderer(plan, scale=0.25, ctx=gl_context, owns_ctx=False)
    out = {}
    try:
        for kind in ("instructions", "break", "questionnaire", "end"):
            screen = screens_of_kind(plan.protocol.session, kind, done=2, total=6)[0]
            phase = screen.phase()
            check = renderer.render({"trial": -1}, phase, "conventional", 0.1, (0.0, 0.0, -1.0))
            assert check.checked and check.ok
            for eye in plan.rig.eyes:
                seen = renderer._renderer.image(eye).copy()
                camera = plan.rig.camera(renderer.display, eye, (0.0, 0.0, -1.0), "conventional")
                with Renderer(blank_scene(), ctx=gl_context, settings=renderer.settings) as blank:
                    blank.render(camera)
                    without = blank.image(eye).copy()
                out[(kind, eye)] = (seen, without)
    finally:
        renderer.close()
    return out


@pytest.fixture(scope="module")
def gl_context():
    from psyop.rendering.renderer import create_headless_context

    ctx = create_headless_context()
    yield ctx
    ctx.release()


@pytest.mark.parametrize("eyes", ["right", "stereo"])
def test_every_screen_shows_its_text_on_the_panel(eyes, gl_context) -> None:
    frames = _screen_text_frames(eyes, gl_context)
    assert {eye for _, eye in frames} == ({"right"} if eyes == "right" else {"left", "right"})
    for (kind, eye), (seen, without) in frames.items():
        differs = np.any(np.abs(seen - without) > 1e-3, axis=2)
        assert 0.0005 < differs.mean() < 0.5, (kind, eye)  # a panel, not the whole view
        rows, cols = np.nonzero(differs)
        h, w = differs.shape
        assert rows.min() < h / 2 < rows.max() and cols.min() < w / 2 < cols.max(), (kind, eye)  # straight ahead
        panel = seen[differs]
        assert (panel.max(axis=1) > 0.7).mean() > 0.01, (kind, eye)  # light ink ...
        assert (panel.max(axis=1) < 0.3).mean() > 0.4, (kind, eye)  # ... on the dark panel
    if eyes == "stereo":  # one panel ahead of the head: each eye sees it at its own place
        left = np.nonzero(np.any(np.abs(np.subtract(*frames[("break", "left")])) > 1e-3, axis=2))[1].min()
        right = np.nonzero(np.any(np.abs(np.subtract(*frames[("break", "right")])) > 1e-3, axis=2))[1].min()
        assert left != right


def test_screen_pages_keep_their_line_breaks() -> None:
    from psyop.rendering.text import WRAP_CHARS as DRAWN_AT, text_image

    assert DRAWN_AT == WRAP_CHARS  # validation counts lines as the panel draws them
    kept = text_image("Welcome.\n\nPress a key.", keep_lines=True)
    joined = text_image("Welcome.\n\nPress a key.")
    assert kept.height_em > joined.height_em and kept.texture.key != joined.texture.key


@pytest.mark.parametrize("phase,screen", [("instructions", 1), ("break", 0), ("questionnaire", 1), ("end", 0)])
def test_render_command_draws_each_screen(phase, screen, tmp_path) -> None:
    import matplotlib.image as mpimg

    protocol = tmp_path / "screens.yaml"
    protocol.write_text(_protocol_text(1))
    out = tmp_path / f"{phase}.png"
    assert main(["render", str(protocol), "--phase", phase, "--screen", str(screen), "--ipd-mm", "64",
                 "--antialiasing", "none", "--crop", "520,600,400,400", "--out", str(out)]) == 0
    side = json.loads(Path(str(out) + ".json").read_text())
    assert side["phase"] == phase and side["screen"] == screen and side["primitives"] == ["response_text"]
    expected = {"instructions": "Answer which one", "break": "2 trials done, 1 left.",
                "questionnaire": "Fatigue", "end": "Thank you!"}[phase]
    assert expected in side["response_text"]
    img = mpimg.imread(out)[:, :, :3]
    assert (img.max(axis=2) > 0.9).any() and (img.max(axis=2) < 0.2).any()  # ink on the dark panel


def test_render_command_refuses_a_missing_screen(tmp_path, capsys) -> None:
    protocol = tmp_path / "screens.yaml"
    protocol.write_text(_protocol_text(1))
    assert main(["render", str(protocol), "--phase", "end", "--screen", "3", "--out", str(tmp_path / "x.png")]) == 2
    assert "--screen must be in 0..0" in capsys.readouterr().err
    plain = REPO / "protocols" / "realism.yaml"
    assert main(["render", str(plain), "--phase", "break", "--out", str(tmp_path / "x.png")]) == 2
    assert "no session: section" in capsys.readouterr().err


BAD = [
    ("ssq with items", "{name: ssq, when: [start, end]}", "{name: ssq, when: [start, end], items: [a]}",
     "session.questionnaires[0]", "its 16 items and 0-3 scale are fixed"),
    ("no items", "{name: ssq, when: [start, end]}",
     "{name: comfort, when: end, scale: {points: 3, labels: [a, b, c]}}", "session.questionnaires[0]",
     "has no items; list the statements under items:"),
    ("one point", "{name: ssq, when: [start, end]}",
     "{name: comfort, when: end, items: [x], scale: {points: 1, labels: [a]}}",
     "session.questionnaires[0].scale.points", "a scale needs 2 to 11 points, got 1"),
    ("labels do not match", "{name: ssq, when: [start, end]}",
     "{name: comfort, when: end, items: [x], scale: {points: 3, labels: [a, b]}}",
     "session.questionnaires[0].scale", "3 points but 2 labels"),
    ("breaks every 0 trials", "every_trials: 2,", "every_trials: 0,", "session.breaks.every_trials",
     "every_trials must be 1 or more"),
    ("an image", "      - text: Answer which", "      - image: a.png\n        text: Answer which",
     "session.instructions.pages[1].image", "image file 'a.png' not found"),
    ("a block that does not exist", "  instructions:\n", "  instructions:\n    at_blocks: [3]\n",
     "session.instructions.at_blocks[0]", "block 3 does not exist"),
]


@pytest.mark.parametrize("name,old,new,where,words", BAD, ids=[b[0] for b in BAD])
def test_bad_session_section_is_one_line_with_file_line_column(name, old, new, where, words, tmp_path,
                                                               capsys) -> None:
    text = _protocol_text(1)
    assert old in text
    bad = text.replace(old, new, 1)
    path = tmp_path / "bad.yaml"
    path.write_text(bad)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    key = re.sub(r"\[\d+\]", "", where.split(".")[-1])  # the line of the key the error names
    needle = next((n for n in new.splitlines() if key in n), new.splitlines()[-1]).strip()
    line = next(i for i, text_line in enumerate(bad.splitlines(), 1) if needle in text_line)
    assert re.search(rf"{re.escape(str(path))}:{line}:\d+: at {re.escape(where)}: ", err), err
    assert words in err


def test_the_docs_example_is_a_valid_session_section() -> None:
    doc = (REPO / "docs" / "protocols.md").read_text()
    section_text = doc[doc.index("### Session screens"):]
    example = re.findall(r"```yaml\n(.*?)```", section_text, flags=re.S)[0]
    text = (REPO / "protocols" / "realism.yaml").read_text().replace(
        "randomisation: {kind: full}", "randomisation: {kind: blocked, by: [pair]}")  # at_blocks: [2] needs 3 blocks
    section = parse_protocol(text + "\n" + example, "docs/protocols.md").session
    assert section is not None and [q.name for q in section.questionnaires] == ["ssq", "comfort"]
    assert section.instructions is not None and section.instructions.at_blocks == [2]


def test_between_blocks_break_questionnaire_and_repeated_instructions(tmp_path) -> None:
    text = (REPO / "protocols" / "realism.yaml").read_text().replace(
        "randomisation: {kind: full}", "randomisation: {kind: blocked, by: [pair]}")
    text = re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 1", text) + """
session:
  instructions:
    pages: [{text: Look at the targets., expected_s: 2}]
    at_blocks: [2]
  breaks: {between_blocks: true, expected_s: 7}
  questionnaires:
    - name: comfort
      when: between_blocks
      items: [The headset was comfortable., The text was easy to read.]
      scale: {points: 5, labels: [disagree, somewhat disagree, neutral, somewhat agree, agree]}
"""
    path = tmp_path / "blocked.yaml"
    path.write_text(text)
    outcome = run_session(load_protocol(path), compile_schedule,
                          SessionOptions(participant="S01", data_root=tmp_path / "data", progress=False, fsync=False,
                                         render="cameras"))
    assert outcome.status == "complete"
    session = tmp_path / "data" / "realism" / "sub-S01" / "ses-1"
    events = pd.read_parquet(session / "events.parquet")
    got = list(events[["screen", "when", "before_trial", "block"]].itertuples(index=False, name=None))
    assert got == [("instructions", "start", 0, 0),
                   ("break", "between_blocks", 1, 1), ("questionnaire", "between_blocks", 1, 1),
                   ("questionnaire", "between_blocks", 1, 1),
                   ("break", "between_blocks", 2, 2), ("questionnaire", "between_blocks", 2, 2),
                   ("questionnaire", "between_blocks", 2, 2), ("instructions", "at_block", 2, 2)]
    answers = pd.read_parquet(session / "questionnaires.parquet")
    assert len(answers) == 4 and answers["answer"].between(0, 4).all() and set(answers["scale_points"]) == {5}
