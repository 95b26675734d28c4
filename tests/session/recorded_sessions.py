"""Recorded simulated sessions: one participant (S01, ``psyop simulate``'s seed for base seed 2020) of each
shipped protocol, its trial, frame and gaze tables and its session.json, stored as values in
tests/session/recorded/<study>/ and compared to a fresh session with a stated tolerance.

Provenance: the values were recorded from 26cd3cb's tree (before the session refactor) by way of the
SHA-256 digests that tree's sessions gave (refactor_goldens.json): :func:`digests` of the stored values equal
those digests exactly. That check hashes stored data, not anything computed at test time, so it holds on every
CPU (tests/session/test_refactor_equality.py::test_recorded_values_are_26cd3cbs).

What is exact and what is close (docs/architecture.md, "Reproducibility across CPUs"):
- integers, strings, booleans, nulls, list lengths, column names and row counts: equal;
- floating-point values: within :data:`FLOAT_RTOL` relative or :data:`FLOAT_ATOL` absolute. The last bits of
  float results differ between CPUs (numpy's AVX-512 and AVX2 kernels round sums and norms differently; measured
  on one AMD EPYC with both: at most 3.1e-16 relative, in ``drift_correction_deg`` and the frames' fixation
  points). 1e-12 is four orders of magnitude above that, and far below anything a participant or an analysis
  sees (1e-12 m, deg, s or D).
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterator
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from psyop.protocol import load_protocol
from psyop.protocol.luminance import UNCALIBRATED_OUTPUT
from psyop.run.simulate import plan_jobs, run_job
from psyop.session.plan import compile_plan
from psyop.session.latency import GAZE_AGE_COLUMNS
from psyop.session.timing import timing_column_names

ROOT = Path(__file__).resolve().parents[2]
RECORDED = Path(__file__).with_name("recorded")
GOLDENS = Path(__file__).with_name("refactor_goldens.json")
STUDIES = sorted(p.stem for p in (ROOT / "protocols").glob("*.yaml"))
FLOAT_RTOL = 1e-12
FLOAT_ATOL = 1e-12

TIMING = ("trial_start_s", "trial_end_s")
#: columns added on purpose after 26cd3cb (issue 29's typed responses): not recorded, and checked instead to be
#: exactly what datacontract.typed_response derives from ``response``
ADDED_AFTER = ("response_value", "outcome")
#: issue 31's measured timing, added after 26cd3cb (and nothing else): session.json's ``summary.frame_timing``
#: block; the trial columns are psyop.session.timing's for the protocol's phases (:func:`measured_timing_columns`)
TIMING_SUMMARY = "frame_timing"
#: models a protocol shows since 26cd3cb, on purpose (issue 26: protocols/egocentric.yaml's reach target is
#: assets/pencil.glb, not the analytic pencil): their session.json ``meshes`` records are not recorded and are
#: checked instead to be the file's own record; the trial, frame and gaze tables did not change with it
ADDED_MODELS = (("pencil.glb", "pencil"),)
#: session.json fields not recorded: wall-clock and machine ones, and inputs (where the protocol lies, its text and
#: hash: protocols may change on purpose, checked to be the protocol file that ran)
SESSION_JSON_EXCLUDED = ("finalised", "runs", "host", "python", "packages", "finalised_files", "rendering",
                         "protocol_file", "protocol_text", "protocol_sha256", "protocol_file_sha256",
                         # issue 40: the protocol's design as the analysis reads it, added after 26cd3cb and checked
                         # instead to be the protocol file's (tests/statistics/test_recorded_design.py)
                         "study_design",
                         # the simulated observer's kind that answered, added after 26cd3cb and checked instead to be
                         # the protocol's (tests/session/test_simulated_sources.py)
                         "observer")
#: session.json keys added since 26cd3cb, on purpose, not recorded and checked instead: issue 27's
#: ``sim_tracker_faults`` (the analysis rebuilds a requested stream from it)
ADDED_SESSION_KEYS = {"sim_tracker_faults": {"dropout_rate_hz": 0.0, "nan_burst_rate_hz": 0.0},
                      # issue 44's gaze-latency rules (none in the shipped protocols: psyop.session.latency)
                      "gaze_latency": {"added_latency_ms": 0.0, "added_latency_factor": None,
                                       "max_gaze_age_ms": None, "max_gaze_age_over_share": 0.05},
                      # issue 42: an uncalibrated display's output stated (psyop.protocol.luminance.output_record)
                      "display_output": {"calibrated": False, "output": UNCALIBRATED_OUTPUT}}
#: issue 44's gaze-to-photon latency, added after 26cd3cb on purpose (psyop.session.latency), not recorded and
#: checked instead (tests/session/test_refactor_equality.py): the trial columns are what the frames give
#: (``trials_gaze_age``), the frame columns say no latency was added and the intrinsic age is the gaze age of
#: every frame with valid gaze, session.json's ``summary.gaze_age`` is what the frames give, and its
#: ``integrity`` names no late trial and no bound
ADDED_LATENCY_TRIAL_COLUMNS = GAZE_AGE_COLUMNS
ADDED_LATENCY_FRAME_COLUMNS = ("added_latency_s", "gaze_age_intrinsic_s")
LATENCY_SUMMARY = "gaze_age"
ADDED_INTEGRITY = {"late_gaze_trials": [], "max_gaze_age_ms": None}


def as_recorded_kind(meta: dict) -> dict:
    """session.json with its response kind spelled as 26cd3cb spelled it. Since issue 40 a kind has one spelling
    (psyop.protocol.kinds: ``response_kind`` and ``response.kind`` are the protocol's ``kind:``, and the
    duplicate ``response.protocol_kind`` is gone); 26cd3cb wrote the session-side spelling (the kind's first
    ``former_names``) in both and the protocol's in ``protocol_kind``. A current record must use the one
    spelling (asserted), and is compared in the recorded form."""
    from psyop.protocol.kinds import KINDS

    name = meta["response_kind"]
    assert name in KINDS and meta["response"]["kind"] == name and "protocol_kind" not in meta["response"], \
        (name, meta["response"])
    former = (KINDS[name].former_names or (name,))[0]
    response = {"kind": former, "protocol_kind": name, **{k: v for k, v in meta["response"].items() if k != "kind"}}
    return {**meta, "response_kind": former, "response": response}


def measured_timing_columns(study: str) -> tuple[str, ...]:
    """The measured-timing columns of ``study``'s trials.parquet: exactly psyop.session.timing's for its phases."""
    return tuple(timing_column_names(compile_plan(load_protocol(ROOT / "protocols" / f"{study}.yaml")).phases))


def simulate(study: str, data_root: Path) -> Path:
    """S01 of ``study`` run headless on the virtual clock exactly as ``psyop simulate`` runs it; its session folder."""
    job = next(j for j in plan_jobs([ROOT / "protocols" / f"{study}.yaml"], 2020, {study: 1})
               if j.participant == "S01")
    run_job(job, data_root)
    return data_root / study / "sub-S01" / "ses-1"


def kept_session_json(session: Path) -> dict:
    """session.json less the fields :data:`SESSION_JSON_EXCLUDED`, :data:`ADDED_SESSION_KEYS`, the timing summary
    and the :data:`ADDED_MODELS` records; ``rendering`` (how images were checked) kept under ``_rendering``."""
    meta = as_recorded_kind(json.loads((session / "session.json").read_text()))
    kept = {k: v for k, v in meta.items() if k not in SESSION_JSON_EXCLUDED and k not in ADDED_SESSION_KEYS}
    if isinstance(kept.get("summary"), dict):
        kept["summary"] = {k: v for k, v in kept["summary"].items() if k not in (TIMING_SUMMARY, LATENCY_SUMMARY)}
    if isinstance(kept.get("integrity"), dict):
        kept["integrity"] = {k: v for k, v in kept["integrity"].items() if k not in ADDED_INTEGRITY}
    if isinstance(kept.get("meshes"), list):
        kept["meshes"] = [m for m in kept["meshes"] if (m["file"], m["node"]) not in ADDED_MODELS]
    return {"_rendering": str(meta["rendering"]), **kept}


def session_values(session: Path, study: str) -> dict[str, pa.Table | dict]:
    """The recorded parts of a session: trials (less the columns added since 26cd3cb), frames, gaze, session.json."""
    trials = pq.read_table(session / "trials.parquet")
    left_out = set(ADDED_AFTER + measured_timing_columns(study) + ADDED_LATENCY_TRIAL_COLUMNS)
    frames = pq.read_table(session / "frames.parquet")
    return {"trials": trials.select([n for n in trials.column_names if n not in left_out]),
            "frames": frames.select([n for n in frames.column_names if n not in ADDED_LATENCY_FRAME_COLUMNS]),
            "gaze": pq.read_table(session / "gaze.parquet"),
            "session_json": kept_session_json(session)}


def recorded_values(study: str) -> dict[str, pa.Table | dict]:
    folder = RECORDED / study
    return {"trials": pq.read_table(folder / "trials.parquet"), "frames": pq.read_table(folder / "frames.parquet"),
            "gaze": pq.read_table(folder / "gaze.parquet"),
            "session_json": json.loads((folder / "session.json").read_text())}


def write_recorded(study: str, values: dict[str, pa.Table | dict]) -> None:
    folder = RECORDED / study
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("trials", "frames", "gaze"):
        table = values[name]
        assert isinstance(table, pa.Table)
        pq.write_table(table, folder / f"{name}.parquet", compression="zstd")
    (folder / "session.json").write_text(json.dumps(values["session_json"], indent=1, sort_keys=True) + "\n")


def _table_digest(table: pa.Table, include: tuple[str, ...] | None = None, exclude: tuple[str, ...] = ()) -> str:
    names = sorted(n for n in table.column_names if n not in exclude and (include is None or n in include))
    rows = table.select(names).to_pylist()
    return hashlib.sha256(json.dumps(rows, sort_keys=True, default=repr).encode()).hexdigest()


def digests(values: dict[str, pa.Table | dict]) -> dict[str, str]:
    """The SHA-256 digests refactor_goldens.json holds, of ``values`` (as 26cd3cb's tests computed them)."""
    trials, frames, gaze, meta = values["trials"], values["frames"], values["gaze"], values["session_json"]
    assert isinstance(trials, pa.Table) and isinstance(frames, pa.Table) and isinstance(gaze, pa.Table)
    assert isinstance(meta, dict)
    kept = {k: v for k, v in meta.items() if k != "_rendering"}
    return {"trials": _table_digest(trials, exclude=TIMING), "trials_timing": _table_digest(trials, include=TIMING),
            "frames": _table_digest(frames), "gaze": _table_digest(gaze),
            "session_json": hashlib.sha256(json.dumps(kept, sort_keys=True).encode()).hexdigest(),
            "rendering": str(meta["_rendering"])}


def golden_digests() -> dict[str, dict[str, str]]:
    """26cd3cb's digests per study (recorded on an AMD EPYC with numpy's kernels narrowed to AVX2)."""
    sets: dict[str, dict[str, dict[str, str]]] = json.loads(GOLDENS.read_text())["sets"]
    (only,) = sets.values()
    return only


def _differences(got: object, want: object, where: str) -> Iterator[str]:
    """Where ``got`` differs from ``want``: floats beyond the tolerance, anything else unequal."""
    if isinstance(want, float) and isinstance(got, float):
        if math.isnan(want) or math.isnan(got):
            if not (math.isnan(want) and math.isnan(got)):
                yield f"{where}: {got!r} != {want!r}"
        elif not math.isclose(got, want, rel_tol=FLOAT_RTOL, abs_tol=FLOAT_ATOL):
            yield f"{where}: {got!r} != {want!r} (differs by {abs(got - want):.3g})"
    elif isinstance(want, dict) and isinstance(got, dict):
        if sorted(got) != sorted(want):
            yield f"{where}: keys {sorted(set(got) ^ set(want))} in one only"
        for key in sorted(set(got) & set(want)):
            yield from _differences(got[key], want[key], f"{where}.{key}")
    elif isinstance(want, list) and isinstance(got, list):
        if len(got) != len(want):
            yield f"{where}: {len(got)} items != {len(want)}"
        for i, (a, b) in enumerate(zip(got, want)):
            yield from _differences(a, b, f"{where}[{i}]")
    elif type(got) is not type(want) or got != want:
        yield f"{where}: {got!r} != {want!r}"


def differences(got: pa.Table | dict, want: pa.Table | dict, name: str) -> list[str]:
    """Every difference of ``got`` from the recorded ``want`` (a table: column by column, row by row)."""
    if isinstance(got, pa.Table) and isinstance(want, pa.Table):
        if sorted(got.column_names) != sorted(want.column_names):
            return [f"{name}: columns {sorted(set(got.column_names) ^ set(want.column_names))} in one only"]
        if got.num_rows != want.num_rows:
            return [f"{name}: {got.num_rows} rows != {want.num_rows}"]
        out: list[str] = []
        for column in sorted(want.column_names):
            if got.schema.field(column).type != want.schema.field(column).type:
                out.append(f"{name}.{column}: type {got.schema.field(column).type} != {want.schema.field(column).type}")
                continue
            out += _differences(got.column(column).to_pylist(), want.column(column).to_pylist(), f"{name}.{column}")
        return out
    return list(_differences(got, want, name))


def record(data_root: Path) -> None:
    """Simulate S01 of every shipped protocol into ``data_root`` and store its values in tests/session/recorded/,
    only if their digests equal 26cd3cb's (run with numpy's and OpenBLAS's kernels narrowed to AVX2, as the digests
    were: ``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR" OPENBLAS_CORETYPE=Haswell``)."""
    golden = golden_digests()
    for study in STUDIES:
        values = session_values(simulate(study, data_root), study)
        got = digests(values)
        differing = [k for k in got if got[k] != golden[study][k]]
        if differing:
            raise SystemExit(f"{study}: not 26cd3cb's values ({differing} differ); nothing recorded for it")
        write_recorded(study, values)
        print(f"{study}: recorded ({', '.join(f'{k} {t.num_rows} rows' for k, t in values.items() if isinstance(t, pa.Table))})")


if __name__ == "__main__":
    import sys
    import tempfile

    sys.path.insert(0, str(ROOT))
    with tempfile.TemporaryDirectory() as tmp:
        record(Path(tmp))
