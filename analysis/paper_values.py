"""The statistics the paper reports (Konrad et al. 2020, main text sec. 5-6), each with the criteria that
decide whether psyop's result reaches the same conclusion.

Each :class:`PaperStat` names the study JSON (results/<file>.json) psyop's value comes from, and its
``psyop`` function returns psyop's value as text with one :class:`Check` per criterion that applies
(:data:`CRITERION`):

- **conclusion** (a test): both significant or both not at the paper's alpha (0.05, psyop's p after the
  same correction), and where the paper states a direction (a post-hoc "higher", a positive slope,
  "greater than 50 %"), psyop's effect has the same sign;
- **value** (an estimate): the paper's number lies inside psyop's 95 % interval.

A row agrees only when every check it has passed; each row names its checks and their results.
"""

from __future__ import annotations

from collections.abc import Callable
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ALPHA = 0.05
MODE_NAMES = {"ocular": "ocular parallax", "reversed": "reversed ocular parallax", "conventional": "conventional"}

#: The agreement criterion, as results/summary.md states it.
CRITERION = ("A row agrees when every criterion it has passes. *Conclusion* (a test): psyop's test and the "
             "paper's are both significant or both not at the paper's alpha (0.05, after the same correction), "
             "and where the paper states a direction (a higher mode, a positive slope, more than 50 %), psyop's "
             "effect has the same sign. *Value* (an estimate): the paper's number lies inside psyop's 95 % "
             "interval. An estimate that the paper also draws a conclusion from (the discrimination slope: "
             "thresholds increase with offset) must pass both.")


@dataclass(frozen=True)
class Check:
    """One criterion applied to one row: its kind ('conclusion' or 'value'), what was compared, and whether
    it passed (None: not applicable, e.g. not testable)."""

    kind: str
    text: str
    passed: bool | None

    def describe(self) -> str:
        verdict = "n/a" if self.passed is None else "passed" if self.passed else "failed"
        return f"{self.kind} {verdict} ({self.text})"


Judged = tuple[str, list[Check]]


@dataclass(frozen=True)
class PaperStat:
    study: str  # study JSON stem
    statistic: str
    paper: str  # as the paper writes it
    paper_conclusion: str  # 'significant', 'not significant', or a value claim
    psyop: Callable[[dict], Judged]  # study payload -> (psyop's value, the checks of each criterion)


def _fmt_p(p: float | None) -> str:
    if p is None:
        return "p = n/a"
    return "p < 0.0001" if p < 1e-4 else "p < 0.001" if p < 1e-3 else f"p = {p:.3g}"


def _significance(p: float, significant: bool) -> Check:
    return Check("conclusion", f"paper {'significant' if significant else 'not significant'}, psyop "
                 f"{'significant' if p < ALPHA else 'not significant'} at alpha {ALPHA}", (p < ALPHA) == significant)


def _anova(effect: str, significant: bool) -> Callable[[dict], Judged]:
    def get(s: dict) -> Judged:
        row = next((r for r in s.get("anova", []) if r["effect"] == effect), None)
        if row is None or row.get("status", "ok") != "ok" or row.get("p_gg") is None:
            status = row.get("status") if row else "missing"
            return (f"not testable ({status})", [Check("conclusion", f"not testable: {status}", None)])
        text = s["summary"][f"ordinal rm-ANOVA: {effect}"]
        return text, [_significance(row["p_gg"], significant)]
    return get


def _posthoc(sep: float, a: str, b: str, significant: bool) -> Callable[[dict], Judged]:
    def get(s: dict) -> Judged:
        for r in s.get("posthoc", []):
            if float(r["separation_D"]) == sep and {r["A"], r["B"]} == {a, b}:
                if r.get("p_bonf") is None:
                    return ("not testable", [Check("conclusion", "not testable", None)])
                first = r["A"] if r["mean_A"] >= r["mean_B"] else r["B"]
                text = (f"{MODE_NAMES[first]} higher, t({r['dof']:.0f}) = {abs(r['T']):.2f}, {_fmt_p(r['p_bonf'])} "
                        f"(Bonferroni x{int(r['m'])})")
                checks = [_significance(r["p_bonf"], significant)]
                if significant:
                    checks.append(Check("conclusion", f"paper {MODE_NAMES[a]} higher, psyop {MODE_NAMES[first]} higher",
                                        first == a))
                return text, checks
        return ("missing", [Check("conclusion", "missing", None)])
    return get


def _binomial(first: str, second: str, significant: bool) -> Callable[[dict], Judged]:
    def get(s: dict) -> Judged:
        for r in s.get("preferences", []):
            if r["first"] == first and r["second"] == second:
                checks = [_significance(r["p"], significant)]
                if significant:
                    checks.append(Check("conclusion", f"paper > 50 %, psyop {100 * r['proportion']:.1f} %",
                                        r["proportion"] > 0.5))
                return (f"{100 * r['proportion']:.1f} % ({r['k']}/{r['n']}), {_fmt_p(r['p'])}", checks)
        return ("missing", [Check("conclusion", "missing", None)])
    return get


def _in_ci(value: float, getter: Callable[[dict], tuple[float, float, float, str]],
           positive: bool = False) -> Callable[[dict], Judged]:
    """The paper's ``value`` inside psyop's 95 % interval; with ``positive`` the paper also concludes the
    estimate is above zero, so psyop's interval must lie above zero too (a significant positive estimate)."""

    def get(s: dict) -> Judged:
        try:
            est, lo, hi, unit = getter(s)
        except (KeyError, TypeError, StopIteration):
            return ("missing", [Check("value", "missing", None)])
        if est is None or lo is None or hi is None:
            return ("not computed", [Check("value", "not computed", None)])
        checks = [Check("value", f"paper {value:g} {'inside' if lo <= value <= hi else 'outside'} psyop's 95 % CI",
                        lo <= value <= hi)]
        if positive:
            where = "above 0" if lo > 0 else "below 0" if hi < 0 else "includes 0"
            checks.append(Check("conclusion", f"paper positive, psyop's 95 % CI {where}", lo > 0))
        return f"{est:.3f}{unit} [95 % CI {lo:.3f}, {hi:.3f}]", checks
    return get


def _reach_line(rendering: str, what: str):
    def getter(s: dict):
        r = next(f for f in s["fits"] if f["rendering"] == rendering)
        return r[what], r[f"{what}_ci_low"], r[f"{what}_ci_high"], ""
    return getter


def _reach_difference(s: dict) -> Judged:
    m, c = s.get("mixed"), s.get("comparison")
    if not m:
        return ("missing", [Check("conclusion", "missing", None)])
    if m.get("joint_test", "Wald chi2") == "Wald chi2":
        joint = f"chi2(2) = {m['joint_chi2']:.2f}"
    else:  # the CR2 fallback: an F with its small-sample denominator df
        joint = f"F(2, {m['joint_df_denom']:.2f}) = {m['joint_statistic']:.2f} ({m['joint_test']})"
    if m.get("flags"):
        joint += f" [flags: {m['flags']}]"
    text = (f"primary {m['method'].split(',')[0]}: {joint}, "
            f"{_fmt_p(m['joint_p'])}; "
            f"pooled regression F({c['joint_df1']}, {c['joint_df2']}) = {c['joint_F']:.2f}, {_fmt_p(c['joint_p'])}")
    if m.get("fallback_reason"):
        text += f" (fallback: {m['fallback_reason']})"
    if m.get("joint_p") is None or m["joint_p"] != m["joint_p"]:  # None or NaN: refused, not judged
        return text, [Check("conclusion", "not testable: " + (m.get("flag_text") or "no p"), None)]
    return text, [_significance(m["joint_p"], False)]


def _back_effect(s: dict) -> Judged:
    rows = s.get("anova_back_D")
    if not rows:
        return (s["summary"].get("effect of back distance on threshold (rm-ANOVA)", "not computed"),
                [Check("conclusion", "not computed", None)])
    row = rows[0]
    if row.get("status", "ok") != "ok":
        return (f"not testable ({row['status']})", [Check("conclusion", f"not testable: {row['status']}", None)])
    return s["summary"]["effect of back distance on threshold (rm-ANOVA)"], [_significance(row["p_gg"], False)]


PAPER: list[PaperStat] = [
    PaperStat("detection_thresholds", "detection threshold (mean)", "approximately 0.36 D", "0.36 D",
              _in_ci(0.36, lambda s: (s["mean_threshold_D"], *s["mean_threshold_ci_D"], " D"))),
    PaperStat("detection_thresholds", "effect of back distance on threshold", "thresholds invariant to back distance",
              "no effect", _back_effect),
    PaperStat("discrimination_fit", "slope of threshold vs offset", "0.11 (thresholds increase with offset)",
              "0.11, positive",
              _in_ci(0.11, lambda s: (s["linear_fit"]["slope"], s["linear_fit"]["slope_ci_low"], s["linear_fit"]["slope_ci_high"], ""),
                     positive=True)),
    PaperStat("discrimination_fit", "intercept of threshold vs offset", "0.38 D", "0.38 D",
              _in_ci(0.38, lambda s: (s["linear_fit"]["intercept"], s["linear_fit"]["intercept_ci_low"],
                                      s["linear_fit"]["intercept_ci_high"], " D"))),
    PaperStat("ordinal", "rendering mode (rm-ANOVA, GG)", "F(1.7, 30.65) = 17.98, p < 0.0001", "significant",
              _anova("mode", True)),
    PaperStat("ordinal", "separation (rm-ANOVA)", "F(1, 18) = 8.14, p < 0.05", "significant", _anova("separation_D", True)),
    PaperStat("ordinal", "mode x separation (rm-ANOVA, GG)", "F(1.78, 31.96) = 0.42, p = 0.64", "not significant",
              _anova("mode * separation_D", False)),
    PaperStat("ordinal", "1 D: ocular parallax vs conventional", "ocular parallax higher, p < 0.001", "significant",
              _posthoc(1.0, "ocular", "conventional", True)),
    PaperStat("ordinal", "1 D: ocular parallax vs reversed", "not significant", "not significant",
              _posthoc(1.0, "ocular", "reversed", False)),
    PaperStat("ordinal", "1 D: reversed vs conventional", "not significant", "not significant",
              _posthoc(1.0, "reversed", "conventional", False)),
    PaperStat("ordinal", "2 D: ocular parallax vs conventional", "ocular parallax higher, p < 0.001", "significant",
              _posthoc(2.0, "ocular", "conventional", True)),
    PaperStat("ordinal", "2 D: ocular parallax vs reversed", "ocular parallax higher, p < 0.05", "significant",
              _posthoc(2.0, "ocular", "reversed", True)),
    PaperStat("ordinal", "2 D: reversed vs conventional", "reversed higher, p < 0.05", "significant",
              _posthoc(2.0, "reversed", "conventional", True)),
    PaperStat("egocentric", "slope, ocular parallax enabled", "1.141", "1.141", _in_ci(1.141, _reach_line("enabled", "slope"))),
    PaperStat("egocentric", "slope, ocular parallax disabled", "1.128", "1.128", _in_ci(1.128, _reach_line("disabled", "slope"))),
    PaperStat("egocentric", "intercept, enabled", "0.167", "0.167", _in_ci(0.167, _reach_line("enabled", "intercept"))),
    PaperStat("egocentric", "intercept, disabled", "0.165", "0.165", _in_ci(0.165, _reach_line("disabled", "intercept"))),
    PaperStat("egocentric", "enabled vs disabled (slope and intercept)", "multiple regression: not significant",
              "not significant", _reach_difference),
    PaperStat("realism", "ocular parallax over conventional", "76.8 %, p < 0.001 (one-tailed binomial)", "significant",
              _binomial("ocular", "conventional", True)),
    PaperStat("realism", "reversed over conventional", "75.1 %, p < 0.001 (one-tailed binomial)", "significant",
              _binomial("reversed", "conventional", True)),
    PaperStat("realism", "ocular parallax over reversed", "49.1 %, not significant", "not significant",
              _binomial("ocular", "reversed", False)),
]


#: The paper's studies: results key -> (the shipped protocol file in protocols/, the analysis whose
#: results JSON gives its rows). A results JSON counts for the paper only when its sessions ran exactly
#: this file (its ``protocol_sha256`` list is this file's hash alone).
PAPER_PROTOCOLS: dict[str, tuple[str, str]] = {
    "detection_thresholds": ("detection.yaml", "thresholds"),
    "discrimination_fit": ("discrimination.yaml", "linear_fit"),
    "ordinal": ("ordinal.yaml", "ordinal"),
    "egocentric": ("egocentric.yaml", "reach"),
    "realism": ("realism.yaml", "preferences"),
}


def paper_hashes(protocols_dir: Path) -> dict[str, str]:
    """results key -> the sha256 of the paper's protocol file (as psyop.protocol records it: the file's
    UTF-8 text); a UserError naming a missing file."""
    from psyop.errors import UserError

    out = {}
    for key, (name, _) in PAPER_PROTOCOLS.items():
        path = Path(protocols_dir) / name
        if not path.is_file():
            raise UserError(f"the paper's protocol {name} is missing; give --protocols DIR holding the paper's "
                            "protocols", str(path))
        out[key] = hashlib.sha256(path.read_bytes().decode("utf-8").encode("utf-8")).hexdigest()
    return out


def rows_for(studies: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per paper statistic: study, statistic, paper, psyop, agrees ('yes'/'no'/'n/a'; 'n/a' when a
    check could not be applied and none failed), and ``criteria``: each check and its result."""
    out = []
    for stat in PAPER:
        payload = studies.get(stat.study)
        if payload is None:
            text, checks = "study not run", [Check("conclusion", "study not run", None)]
        else:
            try:
                text, checks = stat.psyop(payload)
            except (KeyError, TypeError, StopIteration) as exc:
                text, checks = f"missing ({exc})", [Check("conclusion", f"missing {exc}", None)]
        agrees = ("no" if any(c.passed is False for c in checks) else
                  "n/a" if any(c.passed is None for c in checks) else "yes")
        out.append({"study": stat.study, "statistic": stat.statistic, "paper": stat.paper,
                    "paper_conclusion": stat.paper_conclusion, "psyop": text, "agrees": agrees,
                    "criteria": "; ".join(c.describe() for c in checks),
                    "checks": [{"kind": c.kind, "text": c.text, "passed": c.passed} for c in checks]})
    return out
