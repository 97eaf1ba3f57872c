"""The viewer's server: the JSON API and the page (docs/viewer.md).

:func:`create_app` builds the FastAPI app; ``python -m billiards.web`` serves it with uvicorn.
Every endpoint that computes is a plain ``def`` (FastAPI runs it in its thread pool), so a slow
agent or a league replay does not hold up the other requests. Bad input is a 4xx whose JSON
``error`` says what is wrong (:data:`STATUS`): Bad Request for a body that is not JSON,
Unprocessable Content for a value out of its range (balls overlapping or off the table, an
action outside the box, an unknown preset or agent), Forbidden for a path outside the folders
the viewer reads, Not Found for what does not exist, Conflict for a shot in a match that is over
or for a turn that is not the match's current one (a repeated or stale request).
Every error, FastAPI's and Starlette's own included (an unknown route, a method a route does not
take), has that one shape, ``{"error": "<one sentence>"}``; a bug is a 500 with a generic sentence.
:class:`.guard.Guard` answers only the viewer's own host names and refuses writes from other
origins (docs/reliability.md).
"""

from __future__ import annotations

import atexit
import sys
import threading
import time
from collections.abc import Iterable
from http import HTTPStatus
from pathlib import Path

import numpy as np
from fastapi import FastAPI, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, JSONResponse
from starlette.exceptions import HTTPException

from billiards.files import OUTPUTS, ROOT, LedgerError, RunLockedError, display_path
from billiards.physics import DEFAULT_PRESET

from . import catalogue
from . import sim
from .guard import Guard, error, host_names
from .match import HUMAN, Matches, MatchError, MatchMoved
from .models import AgentRequest, ConsideredRequest, MatchRequest, MatchShotRequest, ShotRequest
from .runs import PathRefused, ReplayRefused, RunNotFound, RunStore

# the answers' statuses, by name (HTTP's numbers)
BAD, REFUSED, MISSING, CONFLICT = HTTPStatus.BAD_REQUEST, HTTPStatus.FORBIDDEN, HTTPStatus.NOT_FOUND, HTTPStatus.CONFLICT
INVALID, FAILED, ELSEWHERE = HTTPStatus.UNPROCESSABLE_ENTITY, HTTPStatus.INTERNAL_SERVER_ERROR, HTTPStatus.MISDIRECTED_REQUEST
STATUS = {"bad_json": BAD, "invalid": INVALID, "outside": REFUSED, "not_found": MISSING, "match_over": CONFLICT, "stale_turn": CONFLICT,
          "bug": FAILED, "other_host": ELSEWHERE, "other_origin": REFUSED}  # the last two: Guard's
STATIC = Path(__file__).resolve().parent / "static"
STATIC_FILES = {"app.js": "text/javascript", "style.css": "text/css"}
DEFAULT_OUT = OUTPUTS / "web"


def _error(status: int, message: str) -> JSONResponse:
    return error(status, message)


def _http_message(request: Request, exc: HTTPException) -> str:
    """One sentence for Starlette's own errors: an unknown route, a method a route does not take."""
    method, path = request.method, request.url.path
    if exc.status_code == HTTPStatus.NOT_FOUND:
        return f"no page or endpoint {method} {path!r} (the API is docs/viewer.md's)"
    if exc.status_code == HTTPStatus.METHOD_NOT_ALLOWED:
        allowed = (exc.headers or {}).get("Allow")
        return f"{path!r} does not take {method}" + (f" (it takes {allowed})" if allowed else "")
    detail = exc.detail if isinstance(exc.detail, str) else None
    try:
        phrase = HTTPStatus(exc.status_code).phrase
    except ValueError:
        phrase = f"status {exc.status_code}"
    return detail or phrase


def _validation_message(errors: list[dict]) -> tuple[int, str]:
    """(status, one readable sentence) for pydantic's errors: Bad Request for a body that is not JSON."""
    if any(e.get("type") == "json_invalid" for e in errors):
        e = next(e for e in errors if e.get("type") == "json_invalid")
        return BAD, f"malformed JSON: {e.get('ctx', {}).get('error', e.get('msg'))}"
    parts = []
    for e in errors[:5]:
        loc = ".".join(str(x) for x in e.get("loc", ()) if x != "body") or "body"
        msg = str(e.get("msg", "invalid")).removeprefix("Value error, ")
        parts.append(f"{loc}: {msg}")
    return INVALID, "; ".join(parts)


def _quietly(fn) -> None:
    try:
        fn()
    except Exception:  # noqa: BLE001 - a warm-up only: the request that needs it says what is wrong
        pass


_BACKGROUND: list[threading.Thread] = []  # the apps' threads that work on the side, joined at exit


def _join_background(timeout_s: float = 120.0) -> None:
    """Let the side threads end before the interpreter does: one killed inside torch's or numba's
    native code as the process exits aborts it (``terminate called without an active exception``)."""
    deadline = time.monotonic() + timeout_s
    for t in list(_BACKGROUND):
        t.join(max(0.0, deadline - time.monotonic()))


atexit.register(_join_background)


def _on_the_side(fn, name: str) -> None:
    _BACKGROUND[:] = [t for t in _BACKGROUND if t.is_alive()]
    t = threading.Thread(target=_quietly, args=(fn,), daemon=True, name=name)
    _BACKGROUND.append(t)
    t.start()


class Simulator:
    """Whether numba's kernels of the simulator were cached when the app started, and the warm-up
    that compiles (or loads) them in a thread of its own, so that the page can say it prepares
    the simulator (first use on a machine: :data:`billiards.physics.warmup.WARM_UP_SECONDS`,
    about 15 s on two cores) instead of sitting silent."""

    def __init__(self):
        from billiards.physics import warmup

        self.expected_s = int(getattr(warmup, "WARM_UP_SECONDS", 60))
        self.cached = warmup.kernels_cached()
        self.ready = self.cached  # cached: numba loads each kernel on its first call, in well under a second
        self.started = time.monotonic()
        self.seconds: float | None = None
        self.error: str | None = None

    def warm(self) -> None:
        from billiards.physics.warmup import warm_up

        try:
            self.seconds = warm_up(log=lambda line: print(line, file=sys.stderr, flush=True))  # the server's console says so too
        except Exception as err:  # noqa: BLE001 - the requests that need the simulator say what is wrong
            self.error = f"{type(err).__name__}: {err}"
        self.ready = True

    def state(self) -> dict:
        elapsed = 0.0 if self.cached else self.seconds if self.seconds is not None else time.monotonic() - self.started
        return {"cached": self.cached, "ready": self.ready, "expected_s": 0 if self.cached else self.expected_s,
                "elapsed_s": round(elapsed, 1), "error": self.error}


def create_app(run_dirs=(), out_dir: Path | str | None = DEFAULT_OUT, root: Path = ROOT, hosts: Iterable[str] = ()) -> FastAPI:
    """The viewer's app: runs read from ``root/results``, ``out_dir`` (where played matches are
    saved; None: not saved) and ``run_dirs``. It answers the loopback names (localhost,
    127.0.0.1, [::1]) and ``hosts`` (the address it binds, ``--allow-host`` names; a name that
    is not one raises ValueError), on any port."""
    names = host_names(hosts)
    app = FastAPI(title="billiards viewer", description="Korean 4-ball: shots, agents, replays and matches", version="1")
    app.add_middleware(Guard, hosts=names)
    app.state.hosts = names
    out = Path(out_dir) if out_dir is not None else None
    store = RunStore(root, run_dirs, out)
    matches = Matches(out)
    simulator = Simulator()
    app.state.store, app.state.matches, app.state.simulator = store, matches, simulator
    if not simulator.ready:  # first use on this machine: the simulator's kernels compiled on the side (about 15 s)
        _on_the_side(simulator.warm, "viewer-warm-up")
    # which training runs have shipped weights: read from the policy files (torch loads them) on the side, so the
    # page's first GET /api/runs does not wait for it
    _on_the_side(store.policy_sources, "viewer-policies")

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError):
        status, message = _validation_message(list(exc.errors()))
        return _error(status, message)

    @app.exception_handler(HTTPException)
    async def _http(request: Request, exc: HTTPException):
        return error(exc.status_code, _http_message(request, exc), headers=exc.headers)

    # a bug (an exception no route answered) is Guard's: logged with its traceback, answered 500 with a generic sentence

    # ------------------------------------------------------------------------- the page

    @app.get("/", include_in_schema=False)
    def index():
        return FileResponse(STATIC / "index.html", media_type="text/html")

    @app.get("/static/{name}", include_in_schema=False)
    def static(name: str):
        if name not in STATIC_FILES:
            return _error(MISSING, f"no static file {name!r}")
        return FileResponse(STATIC / name, media_type=STATIC_FILES[name])

    @app.get("/favicon.ico", include_in_schema=False)
    def favicon():
        from fastapi import Response

        return Response(status_code=204)

    # ------------------------------------------------------------------------- the API

    @app.get("/api/config")
    def config():
        """The presets (tables to draw, noise models), the agents and the league players."""
        return JSONResponse({**sim.presets(), "agents": catalogue.catalogue(root), "opponents": catalogue.league_names(root),
                             "default_physics": DEFAULT_PRESET})

    @app.post("/api/shot")
    def shot(body: ShotRequest):
        """One shot, exactly: the final table, the outcome, every ball's path."""
        try:
            out = sim.shot(body.positions, body.action, physics=body.physics, noise=body.noise, seed=body.seed,
                           level=body.level, shooter=body.shooter, dt=body.dt, with_paths=body.paths)
        except ValueError as err:
            return _error(INVALID, str(err))
        return JSONResponse(out)

    @app.post("/api/agent")
    def agent(body: AgentRequest):
        """An agent's shot for a table (white to play) and what it considered."""
        from billiards.bench.adapters import AgentError
        from billiards.physics import check_positions

        try:
            check_positions(body.positions, body.physics)
            out = catalogue.ask(body.agent, body.positions, physics=body.physics, noise=body.noise, seed=body.seed,
                                 level=body.level, replays=body.replays, root=root)
        except catalogue.UnknownAgent as err:
            return _error(INVALID, str(err))
        except (AgentError, ValueError) as err:
            return _error(INVALID, f"agent {body.agent}: {err}")
        return JSONResponse(out)

    @app.post("/api/considered")
    def considered(body: ConsideredRequest):
        """What the agent of a recorded run (or of the list) considers for a recorded shot's table:
        its candidates and estimates, asked again, and the recorded shot replayed under the noise."""
        from billiards.bench.adapters import AgentError
        from billiards.envs.sagu import shooter_view
        from billiards.physics import check_actions, check_positions

        try:
            if body.run is not None:
                kind, real = store.kind_of(body.run)
                if kind == "scorecard":
                    entry = _scorecard_entry(real)
                else:
                    entry = catalogue.search_run_entry(real)
            else:
                entry = catalogue.get_entry(body.agent, body.physics, body.noise, root)
            check_positions(shooter_view(np.asarray(body.positions, dtype=np.float64), body.shooter), entry.params)
            if body.commanded is not None:
                check_actions(np.asarray(body.commanded, dtype=np.float64))
            out = catalogue.reconsider(entry, body.positions, body.commanded, shooter=body.shooter, seed=body.seed,
                                        level=body.level, replays=body.replays)
        except PathRefused as err:
            return _error(REFUSED, str(err))
        except RunNotFound as err:
            return _error(MISSING, str(err))
        except catalogue.UnknownAgent as err:
            return _error(INVALID, str(err))
        except (AgentError, ReplayRefused, LedgerError, ValueError) as err:
            return _error(INVALID, str(err))
        return JSONResponse({**out, "run": body.run})

    def _scorecard_entry(real: Path):
        from . import replays

        ev, track, why = replays.read_scorecard(real)
        spec = (ev.get("agent") or {}).get("spec")
        refusal = why or replays.scorecard_refusal(spec, root)
        if refusal:
            raise ReplayRefused(f"this scorecard's agent cannot be built: {refusal}")
        spec = spec.strip()
        full = str(root / spec) if spec.endswith(".pt") and not Path(spec).is_absolute() else spec
        return catalogue.bench_entry(full, track)

    @app.get("/api/runs")
    def runs():
        """The recorded runs the replay view opens."""
        return JSONResponse({"runs": store.list_runs(), "folders": [store.display(a) for a in store.allowed]})

    @app.get("/api/run")
    def run(path: str = Query(..., max_length=1000), unit: int | None = Query(None, ge=0, le=10**6)):
        """A run's replayable shots (a league's match ``unit`` is played again)."""
        try:
            return JSONResponse(store.load(path, unit))
        except PathRefused as err:
            return _error(REFUSED, str(err))
        except RunNotFound as err:
            return _error(MISSING, str(err))
        except (LedgerError, ValueError) as err:
            return _error(INVALID, str(err))

    @app.get("/api/simulator")
    def simulator_state():
        """Whether the simulator's kernels were cached at start (else they compile: about 15 s) and whether they are ready."""
        return JSONResponse(simulator.state())

    def _no_match(match_id: str) -> JSONResponse:
        where = display_path(matches.out_dir / "matches") if matches.out_dir is not None else None
        return _error(MISSING, f"no match {match_id!r}" + (f" (the matches played here are saved under {where})" if where else
                                                           " (this viewer keeps its matches in memory only)"))

    def _held(match_id: str):
        """The match, or the error that answers for it."""
        try:
            return matches.get(match_id)
        except KeyError:
            return _no_match(match_id)
        except RunLockedError as err:
            return _error(CONFLICT, f"match {match_id} is being written by another process: {err}")
        except LedgerError as err:
            return _error(INVALID, f"match {match_id} cannot be resumed: {err}")

    @app.post("/api/match")
    def new_match(body: MatchRequest):
        """Start a match against a league player; the player's opening turns if it breaks. A
        repeated ``key`` answers the match it started (no second match)."""
        from billiards.bench.spec import AgentError, AgentSpec, SpecKind

        try:  # a league player by name, or as its spec league:<player>
            parsed = AgentSpec.parse(body.opponent)
        except AgentError:
            parsed = None
        name = parsed.player if parsed is not None and parsed.kind is SpecKind.LEAGUE else body.opponent
        players = catalogue.league_names(root)
        if name not in players:
            return _error(INVALID, f"opponent: no league player {body.opponent!r}; players: {', '.join(players)}")
        try:
            m, shots, repeated = matches.new(key=body.key, opponent=name, noise=body.noise, physics=body.physics, target=body.target,
                                             seed=body.seed, first=body.first, max_innings=body.max_innings)
        except (AgentError, ValueError) as err:
            return _error(INVALID, f"cannot start the match: {err}")
        return JSONResponse({"state": m.state(), "shots": shots, "human": HUMAN, "repeated": repeated})

    @app.get("/api/matches")
    def list_matches():
        """The matches saved in the out folder, the most recent first (to resume one)."""
        return JSONResponse({"matches": matches.listed()})

    @app.get("/api/match/{match_id}")
    def get_match(match_id: str):
        """A match's state (read back from its folder if the server does not hold it) and its last exchange of shots."""
        m = _held(match_id)
        if isinstance(m, JSONResponse):
            return m
        with m.lock:
            return JSONResponse({"state": m.state(), "shots": m.recent(), "human": HUMAN})

    @app.post("/api/match/{match_id}/shot")
    def match_shot(match_id: str, body: MatchShotRequest):
        """The person's shot for the turn it names (the server applies the noise), then the league player's turns."""
        m = _held(match_id)
        if isinstance(m, JSONResponse):
            return m
        try:
            shots = m.human_shot(body.action, body.turn)
        except MatchMoved as err:
            matches.forget(match_id)  # read again from its folder on the next request
            return _error(CONFLICT, str(err))
        except RunLockedError as err:
            return _error(CONFLICT, f"match {match_id} is being written by another process: {err}")
        except MatchError as err:  # over, or a turn that is not the current one
            return _error(CONFLICT, str(err))
        except ValueError as err:
            return _error(INVALID, f"action: {err}")
        return JSONResponse({"state": m.state(), "shots": shots})

    return app


__all__ = ["create_app"]
