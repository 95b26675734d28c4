"""The protocol's ``quality:`` rules applied to per-trial measures (analysis time only; nothing recorded
is changed): which participants and trials are excluded, by which rule (psyop.protocol.quality)."""

from __future__ import annotations

import pandas as pd

from psyop.protocol.quality import QualitySection

#: results/<study>_exclusions.csv: one row per excluded trial (trial NaN: the whole participant)
EXCLUSION_COLUMNS = ("participant", "session", "trial", "level", "rule", "value", "reason")


def _trial_rows(measures: pd.DataFrame, rules: QualitySection) -> list[dict]:
    rows = []
    for rule in rules.trials:
        for _, trial in measures.iterrows():
            if rule.fails(float(trial[rule.measure])):
                rows.append({"participant": trial["participant"], "session": int(trial["session"]),
                             "trial": int(trial["trial"]), "level": "trial", "rule": rule.describe(),
                             "value": float(trial[rule.measure]), "reason": rule.reason or ""})
    return rows


def _participant_rows(measures: pd.DataFrame, rules: QualitySection, excluded_trials: set) -> list[dict]:
    rows = []
    for participant, own in measures.groupby("participant", sort=True):
        for rule in rules.participants:
            median = float(own[rule.measure].median())
            if rule.fails(median):
                rows.append({"participant": participant, "session": -1, "trial": -1, "level": "participant",
                             "rule": f"median {rule.describe()}", "value": median, "reason": rule.reason or ""})
        kept = sum((participant, int(s), int(t)) not in excluded_trials
                   for s, t in zip(own["session"], own["trial"]))
        if rules.min_included_trials is not None and kept < rules.min_included_trials:
            rows.append({"participant": participant, "session": -1, "trial": -1, "level": "participant",
                         "rule": f"included trials < {rules.min_included_trials}", "value": float(kept),
                         "reason": rules.min_included_trials_reason or ""})
    return rows


def apply_rules(measures: pd.DataFrame, rules: QualitySection | None) -> pd.DataFrame:
    """The exclusions (:data:`EXCLUSION_COLUMNS`) the rules make on ``measures`` (columns participant,
    session, trial and the measures). A participant row has session and trial -1; a trial that
    breaks several rules has one row per rule. ``rules`` None: nothing is excluded.

    Examples
    --------
    >>> from psyop.protocol.quality import QualityRule
    >>> m = pd.DataFrame({"participant": ["A", "A", "B"], "session": [1, 1, 1], "trial": [0, 1, 0],
    ...                   "data_loss_share": [0.1, 0.9, 0.2]})
    >>> rules = QualitySection(trials=[QualityRule(measure="data_loss_share", max=0.5)], min_included_trials=2)
    >>> apply_rules(m, rules)[["participant", "trial", "rule"]].values.tolist()
    [['A', 1, 'data_loss_share > 0.5'], ['A', -1, 'included trials < 2'], ['B', -1, 'included trials < 2']]
    """
    if rules is None or measures.empty:
        return pd.DataFrame(columns=list(EXCLUSION_COLUMNS))
    trial_rows = _trial_rows(measures, rules)
    excluded = {(r["participant"], r["session"], r["trial"]) for r in trial_rows}
    rows = trial_rows + _participant_rows(measures, rules, excluded)
    return pd.DataFrame(rows, columns=list(EXCLUSION_COLUMNS))


def included_mask(trials: pd.DataFrame, exclusions: pd.DataFrame) -> pd.Series:
    """True for each row of ``trials`` (participant, session, trial) that no exclusion removes."""
    if exclusions.empty:
        return pd.Series(True, index=trials.index)
    gone_people = set(exclusions.loc[exclusions["level"] == "participant", "participant"].astype(str))
    trial_level = exclusions[exclusions["level"] == "trial"]
    gone = set(zip(trial_level["participant"].astype(str), trial_level["session"].astype(int),
                   trial_level["trial"].astype(int)))
    keys = zip(trials["participant"].astype(str), trials["session"].astype(int), trials["trial"].astype(int))
    return pd.Series([p not in gone_people and (p, s, t) not in gone for p, s, t in keys], index=trials.index)


def unmeasured_sentence(measures: pd.DataFrame, rules: QualitySection | None) -> str:
    """How many trials each rule could not judge (its measure NaN: not measurable), or ''."""
    if rules is None or measures.empty:
        return ""
    names = sorted({rule.measure for rule in [*rules.trials, *rules.participants]})
    counts = {name: int(measures[name].isna().sum()) for name in names if measures[name].isna().any()}
    if not counts:
        return ""
    return ("Not measurable (no rule could judge them): " + ", ".join(f"{name} in {n} of {len(measures)} trials"
                                                                      for name, n in counts.items()) + ".")


def methods_sentence(exclusions: pd.DataFrame, n_participants: int, n_trials: int) -> str:
    """The exclusion counts the way a methods section states them."""
    if exclusions.empty:
        return (f"No gaze-based exclusions: all {n_participants} participants and {n_trials} trials were analysed "
                "(no quality: rule excluded any).")
    people = exclusions[exclusions["level"] == "participant"]
    parts = []
    for (rule, reason), rows in people.groupby(["rule", "reason"], sort=True):
        who = ", ".join(sorted(set(rows["participant"].astype(str))))
        parts.append(f"{rows['participant'].nunique()} ({who}) for {reason or rule} ({rule})")
    trials = exclusions[(exclusions["level"] == "trial") & ~exclusions["participant"].isin(set(people["participant"]))]
    n_people, n_trial = people["participant"].nunique(), len(set(zip(trials["participant"], trials["session"], trials["trial"])))
    text = f"Of {n_participants} participants, {n_people} were excluded" + (": " + "; ".join(parts) if parts else "")
    return text + (f". Of the remaining participants' trials, {n_trial} of {n_trials} were excluded by the trial rules "
                   f"({', '.join(sorted(set(trials['rule'])))})." if n_trial else ". No further trials were excluded.")
