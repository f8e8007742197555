"""Sessions: the run loop as a service any front end drives the same way.

``RunSpec`` (a run as plain data) → ``Session.open`` / ``Session.resume`` / ``Session.branch``
→ ``await session.astep()`` ... with typed events, a person's verdicts and interactive views;
``RunStore`` lists runs, their tree and any candidate they rendered.
"""

from intuitf.session.events import EventLog, RunEvent
from intuitf.session.human import HumanVerdict
from intuitf.session.records import GenerationRecord, RunOutcome, SessionSnapshot
from intuitf.session.rundir import RunDirectory
from intuitf.session.session import Session
from intuitf.session.settings import RunSettings
from intuitf.session.spec import IntentSpec, JudgeSpec, ParentLink, RunSpec, VolumeSpec
from intuitf.session.store import RunStore
from intuitf.session.views import PickResult

__all__ = [
    "EventLog",
    "GenerationRecord",
    "HumanVerdict",
    "IntentSpec",
    "JudgeSpec",
    "ParentLink",
    "PickResult",
    "RunDirectory",
    "RunEvent",
    "RunOutcome",
    "RunSettings",
    "RunSpec",
    "RunStore",
    "Session",
    "SessionSnapshot",
    "VolumeSpec",
]
