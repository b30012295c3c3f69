"""The explorer's web application: the page and its assets (shipped in ``static/``, and the 3-D view's
script shared with the HTML report, :mod:`funicular._static`) and a JSON API.

Every solve is a plain POST that carries the whole state (and the last positions drawn, for a warm
start), so the server keeps nothing between requests. Its answer is the picture and the forces; the
checks (LICQ, the second order) are a second POST carrying the state and the point that solve found,
so the page draws first and shows the verdict when it comes. A bad request gets ``{"error": sentence}``
with status 400 (the solve could not even start) or 422 (the scenario is impossible, e.g. supports
farther apart than the chain); the server itself never stops over a request.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from importlib.resources import files
from pathlib import Path
from typing import Any

from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, JSONResponse, Response
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from funicular._static import VIEW3D
from funicular.errors import FunicularError, ScenarioError
from funicular.explorer import _state

STATIC = Path(str(files("funicular.explorer") / "static"))
MAX_BODY = 1_000_000  # bytes: a state of MAX_NODES nodes with its start is far smaller


def _error(message: str, status: int) -> JSONResponse:
    return JSONResponse({"error": message}, status_code=status)


async def _body(request: Request) -> dict[str, Any]:
    """The request's JSON object; ScenarioError (one sentence) for anything else."""
    raw = await request.body()
    if len(raw) > MAX_BODY:
        raise ScenarioError(f"the request is {len(raw)} bytes; the explorer takes at most {MAX_BODY}.")
    try:
        body = json.loads(raw)
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ScenarioError(f"the request is not valid JSON ({error}).") from None
    if not isinstance(body, dict):
        raise ScenarioError("the request must be a JSON object with a state.")
    return body


def _api(work: Callable[[dict[str, Any]], dict[str, Any]]) -> Callable[[Request], Any]:
    """A POST endpoint running ``work`` on the request's JSON in a worker thread (a solve does not
    block the server), with every error the user can cause answered as one sentence."""

    async def endpoint(request: Request) -> Response:
        try:
            body = await _body(request)
            return JSONResponse(await run_in_threadpool(work, body))
        except ScenarioError as error:
            return _error(str(error), 400)
        except FunicularError as error:  # a well-formed scenario the solver cannot solve (infeasible)
            return _error(str(error), 422)
        except RecursionError:  # a deeply nested document
            return _error("the request is nested too deeply.", 400)

    return endpoint


def _solve(body: dict[str, Any]) -> dict[str, Any]:
    return _state.solve_state(body.get("state"), body.get("start"))


def _check(body: dict[str, Any]) -> dict[str, Any]:
    return _state.check_state(body.get("state"), body.get("point"))


def _toml(body: dict[str, Any]) -> dict[str, Any]:
    return {"toml": _state.toml_of_state(body.get("state"))}


def _load(body: dict[str, Any]) -> dict[str, Any]:
    name = body.get("name")
    if not isinstance(name, str) or name not in _state.scenarios():
        raise ScenarioError(f"{name!r} is not a built-in scenario; built-ins: {', '.join(_state.scenarios())}.")
    return {"state": _state.state_of_scenario(name)}


def create_app(initial: dict[str, Any], source: str) -> Starlette:
    """The application, opening on the scenario state ``initial`` read from ``source`` (a built-in
    name or a scenario file, which the page's menu names)."""
    served = _state.served_entry(source)

    async def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html")

    async def view3d(request: Request) -> Response:
        return FileResponse(VIEW3D, media_type="text/javascript")

    async def start(request: Request) -> Response:
        return JSONResponse(
            {"state": initial, "served": served, "scenarios": _state.scenarios(), "presets": _state.PRESETS}
        )

    return Starlette(
        routes=[
            Route("/", index),
            Route("/view3d.js", view3d),
            Route("/api/start", start),
            Route("/api/solve", _api(_solve), methods=["POST"]),
            Route("/api/check", _api(_check), methods=["POST"]),
            Route("/api/toml", _api(_toml), methods=["POST"]),
            Route("/api/load", _api(_load), methods=["POST"]),
            Mount("/static", StaticFiles(directory=STATIC), name="static"),
        ]
    )
