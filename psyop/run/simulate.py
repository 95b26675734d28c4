"""Simulated datasets: every study at the paper's sample sizes, virtual clock, headless.

Used by ``psyop simulate`` (and ``make figures`` when data/ is empty): demos, power
analysis and checking that the analysis recovers the observers' known parameters.
"""

from __future__ import annotations

import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from psyop.session.gaze.simulated import seed_for

if TYPE_CHECKING:
    from psyop.mesh.load import MeshFiles

#: Participants analysed in the paper (Sec. 5-6): detection 6, discrimination 6, ordinal 19,
#: egocentric 13 (16 minus 3 excluded), realism 19.
PAPER_PARTICIPANTS: dict[str, int] = {"detection": 6, "discrimination": 6, "ordinal": 19, "egocentric": 13, "realism": 19}

# Workers are spawned, not forked: a forked child inherits a parent's OpenGL (llvmpipe)
# context without its threads and hangs (seen in the test suite: Framebuffer.read never returned).
_SPAWN = multiprocessing.get_context("spawn")


@dataclass(frozen=True)
class SimulatedJob:
    protocol: Path
    study: str
    participant: str
    seed: int


def plan_jobs(protocol_paths: list[Path], base_seed: int, participants: dict[str, int] | None = None,
              default_participants: int = 6, mesh_files: dict[Path, MeshFiles] | None = None) -> list[SimulatedJob]:
    """One job per (study, participant); studies without a paper size (or one in ``participants``)
    get ``default_participants``. ``mesh_files``: per protocol path, the cache its models are read into."""
    from psyop.protocol import load_protocol

    sizes = dict(PAPER_PARTICIPANTS, **(participants or {}))
    jobs = []
    for path in protocol_paths:
        protocol = load_protocol(path, meshes=(mesh_files or {}).get(path))
        study = protocol.study.name
        if protocol.observer is None:
            continue
        for i in range(1, sizes.get(study, default_participants) + 1):
            participant = f"S{i:02d}"
            jobs.append(SimulatedJob(path, study, participant, seed_for(base_seed, study, participant)))
    return jobs


def run_job(job: SimulatedJob, data_root: Path, mesh_files: MeshFiles | None = None) -> tuple[str, str, str, int]:
    """Run (or finish) one simulated session; returns (study, participant, status, trials). ``mesh_files``:
    the models already read (in this process), else a cache of this session's own."""
    from psyop.mesh.load import MeshFiles
    from psyop.protocol import load_protocol
    from psyop.schedule import compile_schedule
    from psyop.run.runner import SessionOptions, run_session

    from psyop.session.log.layout import SessionPaths
    from psyop.session.log.record import read_record

    record = read_record(SessionPaths(data_root, job.study, job.participant, 1))  # session.json, typed
    if record is not None and record.status == "complete":
        return job.study, job.participant, "already complete", 0
    # images are rendered and checked in the first participant's session of each study only:
    # the check is of the pipeline, and an OpenGL context per session would double the run time
    from psyop.session.lock import SessionInUse
    from psyop.session.log.store import SessionComplete

    files = mesh_files if mesh_files is not None else MeshFiles(job.protocol.parent)
    options = SessionOptions(participant=job.participant, seed=job.seed, data_root=data_root,
                             progress=False, write_description=False,
                             render="auto" if job.participant == "S01" else "cameras", mesh_files=files)
    try:
        outcome = run_session(load_protocol(job.protocol, meshes=files), compile_schedule, options)
    except SessionInUse as busy:  # another `psyop simulate` (or run) has it: skip it, do the rest
        return job.study, job.participant, f"in use by {busy.holder}, skipped", 0
    except SessionComplete:  # another process completed it since the check above
        return job.study, job.participant, "already complete", 0
    return job.study, job.participant, outcome.status, outcome.n_recorded


def simulate_dataset(protocol_paths: list[Path], data_root: Path, *, jobs: int = 2, base_seed: int = 2020,
                     participants: dict[str, int] | None = None,
                     default_participants: int = 6) -> list[tuple[str, str, str, int]]:
    """Run every job (``jobs`` worker processes) and mark the dataset simulated."""
    from psyop.mesh.load import MeshFiles
    from psyop.session.log.layout import write_dataset_description

    # one model cache per protocol: in one process every session reuses what validation read; spawned
    # workers cannot share it and read each session's models once of their own
    files = {path: MeshFiles(path.parent) for path in protocol_paths}
    planned = plan_jobs(protocol_paths, base_seed, participants, default_participants, files)
    start = time.perf_counter()
    if jobs <= 1:
        results = [run_job(job, data_root, files[job.protocol]) for job in planned]
    else:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=_SPAWN) as pool:
            results = list(pool.map(run_job, planned, [data_root] * len(planned)))
    write_dataset_description(data_root, simulated=True, studies=sorted({j.study for j in planned}))
    _ = time.perf_counter() - start
    return results
