"""``GET /api/info``: what this server is and which evaluators the page may offer."""

from __future__ import annotations

from fastapi import APIRouter, Request
from pydantic import BaseModel

from intuitf.web.common import state
from intuitf.web.schema import COMMON

router = APIRouter(prefix="/api", tags=["info"], responses=COMMON)


class Info(BaseModel):
    version: str
    evaluator: str
    evaluators: list[str]
    runs_dir: str
    max_upload_bytes: int


@router.get("/info", response_model=Info)
def info(request: Request) -> Info:
    from intuitf import __version__
    from intuitf.evaluator.providers import redact_url
    from intuitf.web.app import EVALUATOR_EXAMPLES

    web = state(request)
    return Info(
        version=__version__,
        evaluator=redact_url(web.evaluator) or "metric",
        evaluators=EVALUATOR_EXAMPLES,
        runs_dir=str(web.runs_dir),
        max_upload_bytes=web.max_upload_bytes,
    )
