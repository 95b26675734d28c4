"""A readable text summary of a protocol (``psyop show``)."""

from __future__ import annotations

from psyop.protocol.base import format_level
from psyop.protocol.conditions import condition_label, expand_conditions
from psyop.protocol.model import Protocol
from psyop.schedule.counts import expected_duration_s, trial_count


def _minutes(seconds: float) -> str:
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.1f} s"


def summarise(protocol: Protocol) -> str:
    """Study, display, scene, phases, factors, conditions, counts and expected duration."""
    design = protocol.design
    conditions = expand_conditions(design)
    display = protocol.display
    lines = [f"{protocol.study.name}: {protocol.study.title}"]
    if protocol.study.citation:
        lines.append(f"  citation: {protocol.study.citation}")
    if protocol.study.description:
        lines.append(f"  description: {protocol.study.description}")
    profile = display.profile if isinstance(display.profile, str) else f"{display.profile.name} (inline)"
    eye = display.eye_model if isinstance(display.eye_model, str) else f"NC = {display.eye_model.nc_mm} mm"
    ipd = display.ipd if isinstance(display.ipd, str) else f"{display.ipd.mm} mm"
    lines.append(f"  display: {profile}; eye model: {eye}; ipd: {ipd}; eyes: {protocol.eyes}")
    lines.append("  scene: " + ", ".join(f"{item.id} ({item.kind})" for item in protocol.scene))
    phases = []
    for phase in protocol.trial.phases:
        fixed = getattr(phase, "duration_s", None)
        phases.append(f"{phase.kind} {fixed:g} s" if fixed is not None else f"{phase.kind} ~{phase.expected_s:g} s")
    lines.append("  trial: " + " -> ".join(phases) + f" (~{protocol.trial.expected_duration_s():.1f} s per trial)")
    lines.append(f"  response: {protocol.response.kind}")
    lines.append("  factors:")
    for name, factor in design.factors.items():
        if factor.adaptive is not None:
            a = factor.adaptive
            text = f"adaptive ({a.procedure}, start {a.start:g}, range {a.min:g}..{a.max:g})"
        elif factor.levels is not None:
            text = ", ".join(format_level(v) for v in factor.levels_for(None))
        else:
            assert factor.levels_by is not None
            text = "; ".join(f"{factor.depends_on}={format_level(k)}: "
                             + ", ".join(format_level(v) for v in factor.levels_for(k)) for k in factor.levels_by)
        lines.append(f"    {name}: {text}" + (f"  ({factor.description})" if factor.description else ""))
    lines.append(f"  conditions: {len(conditions)} x {design.repetitions} repetitions"
                 + (f" + {design.practice_trials} practice" if design.practice_trials else "")
                 + f" = {trial_count(protocol)} trials")
    shown = conditions if len(conditions) <= 30 else conditions[:10]
    per_condition = design.repetitions
    for condition in shown:
        lines.append(f"    {condition_label(condition, design) or '(single condition)'}: {per_condition} trials")
    if len(shown) < len(conditions):
        lines.append(f"    ... and {len(conditions) - len(shown)} more conditions")
    randomisation = design.randomisation
    order = randomisation.kind + (f" by {', '.join(randomisation.by)} ({randomisation.block_order} block order)"
                                  if randomisation.kind == "blocked" else "")
    lines.append(f"  order: {order}")
    lines.append(f"  expected duration: {_minutes(expected_duration_s(protocol))} "
                 "(fixed phases plus expected participant-paced phases; no breaks or calibration)")
    validation = protocol.gaze_validation
    if validation is not None:  # not in the expected duration above: how often it runs depends on its require
        bound = "" if validation.require is None else (f"; trials wait for a mean error <= "
                                                       f"{validation.require.max_mean_error_deg:g} deg "
                                                       f"({validation.require.max_attempts} attempts, then stop)")
        lines.append(f"  gaze validation: {len(validation.points_deg)} points at {validation.distance_m:g} m, "
                     f"~{validation.expected_s():.1f} s each, at {', '.join(validation.when)}{bound}")
    if protocol.observer is not None:
        lines.append(f"  simulated observer: {protocol.observer.kind}")
    return "\n".join(lines)
