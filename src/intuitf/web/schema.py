"""What the OpenAPI schema says of errors: every error the API answers has one body,
:class:`ErrorOut`, and each route declares the statuses it can answer with it."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class FieldError(BaseModel):
    loc: list[str | int] = Field(description="where: the field's path")
    msg: str = Field(description="what is wrong with it")


class ErrorOut(BaseModel):
    """The body of every error: what happened, what to do, and which fields were bad."""

    detail: str = Field(description="what happened, in plain words")
    hint: str | None = Field(None, description="what to do about it")
    errors: list[FieldError] | None = Field(None, description="the fields that were not valid")


_WHAT = {
    400: "The request cannot be read (a malformed body or header).",
    404: "No such run, candidate, volume or picture.",
    409: "Not now: the run is going, has ended, or is used by something else.",
    413: "The upload is larger than the server's limit.",
    422: "A field is not valid (named in detail and errors).",
    429: "Too many runs are going at once.",
}


def error_responses(*statuses: int) -> dict[int | str, dict[str, Any]]:
    """``responses=`` of a route or router: the error statuses with their body."""
    return {s: {"model": ErrorOut, "description": _WHAT[s]} for s in statuses}


#: The statuses any API route may answer besides its own success.
COMMON = error_responses(400, 404, 409, 413, 422, 429)
