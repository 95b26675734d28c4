"""Gaze quality of one study: the per-trial measures of every session (psyop.quality, from the
raw gaze stream each session finalised; a ``requested`` simulated stream is rebuilt from its seed and checked
against every recorded sample, else measured from the samples it holds: psyop.quality.resimulate),
the fixation/saccade events (pymovements; built here from the finalised session files, not stored in
them), the protocol's ``quality:`` exclusions and the methods sentence. Writes
results/<study>_gaze_quality.csv, results/<study>_gaze_events.csv, results/<study>_exclusions.csv,
results/<study>_quality.txt, the figure (each measure per participant with the rule thresholds) and
<figure>_samples.png (raw gaze of the first session's first trials against the target).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

from _common import out_path, parser, results_file, run, write_csv, write_text

from psyop.figures.output import save_figure
from psyop.quality.cache import QualityCache
from psyop.quality.figures import plot_measures, plot_sample_trials
from psyop.quality.included import quality_rules, study_quality
from psyop.quality.resimulate import runs_of
from psyop.quality.session import SessionGaze, session_gaze
from psyop.statistics.dataset import session_files

#: the trials the samples figure draws (psyop.quality.figures.plot_sample_trials)
SAMPLE_TRIALS = 3


def _sample_session(directory: Path, measures: pd.DataFrame) -> SessionGaze:
    """The session whose first trials the samples figure draws, from the stream its measures came from: a
    rebuilt stream only over those trials (the start of the whole rebuild, checked over them), any other the
    session's own (a stream whose whole rebuild was refused is not drawn rebuilt from a part)."""
    s = session_gaze(directory, n_trials=SAMPLE_TRIALS)
    if s.stream == "resimulated" and not measures.empty:
        mine = (measures["participant"] == s.participant) & (measures["session"] == s.session)
        if set(measures.loc[mine, "raw_stream"]) != {"resimulated"}:
            return session_gaze(directory)
    return s


def main(argv: list[str] | None = None) -> int:
    args = parser(__doc__, "figures/{study}_gaze_quality.png", study="detection").parse_args(argv)
    sessions = [f.parent for f in session_files(args.data, args.study)]
    rules = quality_rules(sessions)
    quality = study_quality(sessions, rules, QualityCache.beside(args.data))  # docs/quality.md, "The quality cache"
    args.results.mkdir(parents=True, exist_ok=True)
    write_csv(quality.measures, results_file(args.results, args.study, "gaze_quality", "csv"))
    write_csv(quality.events, results_file(args.results, args.study, "gaze_events", "csv"))
    write_csv(quality.exclusions, results_file(args.results, args.study, "exclusions", "csv"))
    write_text(results_file(args.results, args.study, "quality", "txt"), quality.sentence + "\n")
    out = out_path(args)
    if sessions:  # the stream it was measured from (a requested simulated session's rebuilt one)
        first = _sample_session(sessions[0], quality.measures)
        run, trials = (runs_of(first.trials) or [(0, first.trials)])[0]  # one run: each run's clock starts anew
        gaze = first.gaze[first.gaze["run"] == run] if "run" in first.gaze else first.gaze
        save_figure(plot_sample_trials(gaze, trials, first.plan, n_trials=SAMPLE_TRIALS),
                    out.with_name(out.stem + "_samples.png"))
    save_figure(plot_measures(quality.measures, rules, args.study), out)
    print(f"[psyop] {args.study}: {quality.sentence}")
    return 0


if __name__ == "__main__":
    sys.exit(run(main))
