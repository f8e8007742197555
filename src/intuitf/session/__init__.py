"""Sessions: the run loop, stages, the run directory, journal, checkpoints and resume."""

from intuitf.session.rundir import RunDirectory
from intuitf.session.session import GenerationRecord, ProgressEvent, RunOutcome, Session
from intuitf.session.settings import RunSettings

__all__ = [
    "GenerationRecord",
    "ProgressEvent",
    "RunDirectory",
    "RunOutcome",
    "RunSettings",
    "Session",
]
