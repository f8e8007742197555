"""Sessions: the run loop as a service any front end drives the same way.

``RunSpec`` (a run as plain data) → ``Session.open`` / ``Session.resume`` / ``Session.branch``
→ ``await session.astep()`` ... with typed events, a person's verdicts and interactive views;
``RunStore`` lists runs, their tree and any candidate they rendered.
"""

from typing import TYPE_CHECKING

from intuitf._lazy import lazy_exports

if TYPE_CHECKING:  # the names below, for type checkers and editors
    from intuitf.session.events import EventLog, RunEvent
    from intuitf.session.human import HumanVerdict
    from intuitf.session.records import GenerationRecord, RunOutcome, SessionSnapshot
    from intuitf.session.rundir import RunDirectory
    from intuitf.session.session import Session
    from intuitf.session.settings import RunSettings
    from intuitf.session.spec import IntentSpec, JudgeSpec, ParentLink, RunSpec, VolumeSpec
    from intuitf.session.store import RunStore
    from intuitf.session.views import PickResult

_EXPORTS = {
    "EventLog": "intuitf.session.events",
    "RunEvent": "intuitf.session.events",
    "HumanVerdict": "intuitf.session.human",
    "GenerationRecord": "intuitf.session.records",
    "RunOutcome": "intuitf.session.records",
    "SessionSnapshot": "intuitf.session.records",
    "RunDirectory": "intuitf.session.rundir",
    "Session": "intuitf.session.session",
    "RunSettings": "intuitf.session.settings",
    "IntentSpec": "intuitf.session.spec",
    "JudgeSpec": "intuitf.session.spec",
    "ParentLink": "intuitf.session.spec",
    "RunSpec": "intuitf.session.spec",
    "VolumeSpec": "intuitf.session.spec",
    "RunStore": "intuitf.session.store",
    "PickResult": "intuitf.session.views",
}

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

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
