"""The loop's configuration is the plan's facts plus the run's options, each field declared once."""

from __future__ import annotations

import dataclasses

from psyop.session.loop import LoopConfig, LoopFacts, LoopOptions, pursuit_fields
from psyop.session.plan import FixationPath


def _names(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


def test_facts_and_options_are_disjoint_and_make_up_the_config() -> None:
    facts, options = _names(LoopFacts), _names(LoopOptions)
    assert not set(facts) & set(options)
    assert sorted(_names(LoopConfig)) == sorted(facts + options)


def test_config_of_facts_and_options_keeps_every_value() -> None:
    path = FixationPath(12.0, 45.0, 0.8, (3.0, -2.0), "dot")
    facts = LoopFacts(refresh_hz=72.0, **pursuit_fields(path), hand_last_n=4, min_valid_gaze_share=0.7)
    options = LoopOptions(every_frame=False, phase_delay_s=0.25, progress=False)
    config = LoopConfig.of(facts, options)
    for part in (facts, options):
        for name in _names(type(part)):
            assert getattr(config, name) == getattr(part, name), name
    assert (config.pursuit_eccentricity_deg, config.pursuit_speed_deg_s, config.pursuit_id) == (12.0, 45.0, "dot")


def test_no_moving_target_leaves_the_defaults() -> None:
    assert pursuit_fields(None) == {}
    assert LoopFacts(**pursuit_fields(None)) == LoopFacts()
