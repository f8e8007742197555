"""The interactive system in the browser: ``intuitf serve``.

:func:`~intuitf.web.app.create_app` builds the FastAPI app: the page (static ES modules under
``static/``), a JSON API (its OpenAPI schema is the contract with the page), run progress as
server-sent events and volume-view frames over a WebSocket. It drives runs only through
:mod:`intuitf.session`; it binds to 127.0.0.1 with a per-launch token (see
:mod:`intuitf.web.security`).
"""

from intuitf.web.app import create_app

__all__ = ["create_app"]
