"""Durable session logs: append-per-trial Arrow IPC streams, finalised to parquet.

A trial is written as one Arrow IPC record batch, flushed and fsynced before the next
trial starts, so a SIGKILL loses at most the trial in flight. Each run of a session
(first start, every resume) writes its own stream segment; recovery reads the
segments in order and stops at a torn tail.
"""

from psyop.session.log.layout import SessionPaths, session_paths, write_dataset_description
from psyop.session.log.stream import DurableStreamWriter, read_stream_tolerant
from psyop.session.log.store import SessionStore, finalise_session, recover_tables

__all__ = [
    "DurableStreamWriter",
    "SessionPaths",
    "SessionStore",
    "finalise_session",
    "read_stream_tolerant",
    "recover_tables",
    "session_paths",
    "write_dataset_description",
]
