"""The plain re-simulation of one replication, paired with ``psyop power``'s on identical seeds.

For a protocol with constant stimuli and an observer whose answer depends only on the trial row
(two-interval, left/right-nearer, pairwise preference), a replication can skip the session: compile
each participant's schedule with the session seed :func:`psyop.power.replicate.session_seed` gives,
ask the same observer (same seed and participant) for each main trial's answer, and run the same
:func:`psyop.power.study_tests.study_tests` on the table. Its p values must equal the session path's
exactly; a difference means the session (logging, scoring, dataset loading, rendering order) changed
what the analysis sees. Reach observers depend on the rendered geometry, the image observer
(``observer: {kind: image}``) on the rendered frames and adaptive levels on the procedure, so those
protocols are refused (the image observer's at its ``kind:`` line, naming the session path instead).
"""

from __future__ import annotations

import pandas as pd

from psyop.errors import UserError
from psyop.power.replicate import ReplicationResult, ReplicationTask, session_seed
from psyop.power.study_tests import study_tests
from psyop.protocol.model import Protocol


def direct_trials(task: ReplicationTask) -> pd.DataFrame:
    """The trial table the session path would log for ``task``, drawn without sessions."""
    from psyop.power.effects import apply_effects
    from psyop.protocol import parse_protocol
    from psyop.schedule import compile_schedule
    from psyop.session.plan import compile_plan
    from psyop.session.responses.simulated import make_observer

    protocol = apply_effects(parse_protocol(task.protocol_text, task.protocol_name), task.effects)
    if protocol.response.kind == "reach":
        raise UserError("the direct re-simulation needs an observer that answers from the trial row; "
                        "reach answers depend on the rendered geometry", "protocol response")
    plan = compile_plan(protocol)
    params = plan.observer_params()
    if params is None:
        raise UserError("the direct re-simulation needs the protocol's simulated observer (an observer: section)",
                        "protocol observer")
    if params.get("kind") == "image":
        raise UserError(*_image_refusal(protocol))
    if plan.kind.needs_hand_pose or plan.adaptive is not None:
        raise UserError("the direct re-simulation covers constant stimuli answered from the trial row only",
                        "protocol design")
    frames = []
    for j in range(task.participants):
        participant = f"S{j + 1:02d}"
        seed = session_seed(task.seed, task.participants, task.replication, j)
        schedule = compile_schedule(protocol, seed, participant_index=j + 1)  # as the ID S{j+1} gives a session
        observer = make_observer(params, seed=seed, participant=participant)
        main = schedule[~schedule["practice"].astype(bool)] if "practice" in schedule else schedule
        answers = [observer.collect(row, 0.0) for row in main.to_dict("records")]
        table = main.reset_index(drop=True).copy()
        table["study"], table["participant"], table["session"] = protocol.study.name, participant, 1
        table["response"] = [a.response for a in answers]
        table["correct"] = [a.correct for a in answers]
        table["chosen_mode"] = [a.chosen_mode for a in answers]
        frames.append(table)
    return pd.concat(frames, ignore_index=True)


def _image_refusal(protocol: Protocol) -> tuple[str, str]:
    """The one-line refusal of the image observer, located at the protocol's ``observer: kind:``."""
    from psyop.protocol.source import read_yaml

    document = read_yaml(protocol.source_text, protocol.source_name)
    _, mark = document.nearest(("observer", "kind"))
    return ("the image observer answers from the frames a session renders, which the direct re-simulation does not "
            "draw; run `psyop power` (it runs each simulated session, rendering every interval: about 1 s of CPU "
            "per trial at the observer's defaults), or use a schedule-based observer (e.g. kind: psychometric_2afc) "
            "for the direct path", document.location(mark))


def run_direct_replication(task: ReplicationTask) -> ReplicationResult:
    from psyop.power.effects import apply_effects
    from psyop.protocol import parse_protocol

    protocol = apply_effects(parse_protocol(task.protocol_text, task.protocol_name), task.effects)
    trials = direct_trials(task)
    return ReplicationResult(task.participants, task.replication, tuple(study_tests(protocol, trials)), len(trials))
