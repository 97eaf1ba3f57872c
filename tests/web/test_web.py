"""The viewer's JSON API (billiards.web) through FastAPI's TestClient: its shots are the
simulator's bit for bit, bad input is a 4xx with a message and the next request still
succeeds, agents answer, recorded runs list and replay exactly (P3 chains from their ledgers;
benchmark scorecards' units, P1 innings and training evaluations played again, their scores
equal to the recorded ones), a scorecard whose agent names code is refused, what a search
considered is shown for a recorded shot, paths outside the allowed folders are refused, a match
plays to its end and is saved as a league ledger; only the viewer's own host names are answered,
a write from another origin is refused, and every error has one shape, a bug's included."""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("httpx")  # FastAPI's TestClient
from fastapi.testclient import TestClient  # noqa: E402

from billiards.envs.sagu import shooter_view  # noqa: E402
from billiards.files import ROOT, display_path, verify  # noqa: E402
from billiards.physics import canonical_rack, get_params, simulate_shot  # noqa: E402
from billiards.physics.noise import get_noise  # noqa: E402
from billiards.web import create_app  # noqa: E402

P3_RUN = "results/search/paper/table6/geometric/h2_p3"  # a committed exact P3 run (20 chains, their last shots)
NOISY_P3 = "results/noisy_track/headline/position_fastfiz_p3"  # the position-aware search under fastfiz (a table value)
P1_RUN = "results/noisy_track/runs/h2_fastfiz_p1"  # a committed P1: 20 innings x 50 shots of h2 under fastfiz
SCORECARDS = "results/bench/scorecards"
CODE_SPEC = "tests/web/test_web.py:GOOD"  # a spec that names code: never built by the viewer
RACK = canonical_rack().tolist()
GOOD = {"positions": RACK, "action": [1.0, 0.6, 0.2, -0.1]}


@pytest.fixture(scope="module")
def extra_runs(tmp_path_factory):
    """A run directory given on the command line, holding a symlink that leads out of it."""
    d = tmp_path_factory.mktemp("runs")
    (d / "out").symlink_to(ROOT / "billiards")
    code = d / "code_scorecard"  # a scorecard of a committed run, its agent spec changed to one that names code
    code.mkdir()
    src = ROOT / SCORECARDS / "p1-exact-v1" / "random"
    ev = json.loads((src / "evaluation.json").read_text())
    ev["agent"]["spec"] = CODE_SPEC
    (code / "evaluation.json").write_text(json.dumps(ev))
    (code / "units.jsonl").write_bytes((src / "units.jsonl").read_bytes())
    return d


@pytest.fixture(scope="module")
def out_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("web_out")


def viewer(app, **kwargs) -> TestClient:
    """A client of ``app`` at one of the viewer's own names (TestClient's default Host, testserver, is refused)."""
    return TestClient(app, base_url="http://localhost", **kwargs)


@pytest.fixture(scope="module")
def client(extra_runs, out_dir):
    return viewer(create_app(run_dirs=[extra_runs], out_dir=out_dir))


# ----------------------------------------------------------------------------- shots


@pytest.mark.parametrize("action", [[1.0, 0.6, 0.2, -0.1], [math.pi, 0.5, 0.0, 0.0], [4.71238898038469, 0.93, -0.7, 0.55]])
def test_shot_on_the_opening_rack_is_simulate_shot_bit_for_bit(client, action):
    r = client.post("/api/shot", json={"positions": RACK, "action": action})
    assert r.status_code == 200, r.text
    out = r.json()
    res = simulate_shot(np.array(RACK), np.array(action))
    assert out["final"] == res.positions.tolist()  # JSON floats round-trip exactly
    assert (out["result"]["score"], out["result"]["foul"]) == (res.score, res.foul)
    assert out["result"]["cushions"] == res.cushions
    assert list(out["result"]["hits"].values()) == res.hits.tolist()
    assert out["played"] == action
    xy = np.array(out["paths"]["xy"])
    assert xy.shape == (len(out["paths"]["t"]), 4, 2) and np.allclose(xy[0], RACK) and np.allclose(xy[-1], res.positions, atol=1e-5)


def test_a_noisy_shot_is_the_noise_model_then_the_simulator(client):
    action = [1.3, 0.7, 0.1, 0.2]
    r = client.post("/api/shot", json={"positions": RACK, "action": action, "noise": "fastfiz_x5", "seed": 11}).json()
    played = get_noise("fastfiz_x5").perturb(np.array(action)[None], np.random.default_rng(11))[0]
    assert r["played"] == played.tolist() and r["commanded"] == action
    assert r["final"] == simulate_shot(np.array(RACK), played).positions.tolist()


def test_a_yellow_shot_is_simulated_from_the_yellow_view(client):
    action = [0.4, 0.8, 0.0, 0.3]
    r = client.post("/api/shot", json={"positions": RACK, "action": action, "shooter": 1}).json()
    res = simulate_shot(shooter_view(np.array(RACK), 1), np.array(action))
    assert r["final"] == shooter_view(res.positions, 1).tolist()
    assert set(r["result"]["hits"]) == {"white", "red1", "red2"}


# ----------------------------------------------------------------------------- bad input

BAD = [  # (id, method, url, json body or raw bytes, status, words the message holds)
    ("overlap", "POST", "/api/shot", {**GOOD, "positions": [RACK[0], RACK[0], RACK[2], RACK[3]]}, 422, "overlaps"),
    ("off-table", "POST", "/api/shot", {**GOOD, "positions": [[3.0, 1.0], *RACK[1:]]}, 422, "off the table"),
    ("power", "POST", "/api/shot", {**GOOD, "action": [1.0, 1.5, 0.0, 0.0]}, 422, "power p"),
    ("tip", "POST", "/api/shot", {**GOOD, "action": [1.0, 0.5, 2.0, 0.0]}, 422, "tip offset a"),
    ("nan", "POST", "/api/shot", b'{"positions": %s, "action": [NaN, 0.5, 0, 0]}' % json.dumps(RACK).encode(), 422, "finite"),
    ("shape", "POST", "/api/shot", {**GOOD, "positions": RACK[:3]}, 422, "positions"),
    ("bool", "POST", "/api/shot", {**GOOD, "action": [1.0, True, 0.0, 0.0]}, 422, "action.1"),
    ("extra-key", "POST", "/api/shot", {**GOOD, "spin": 1}, 422, "spin"),
    ("physics", "POST", "/api/shot", {**GOOD, "physics": "snooker"}, 422, "unknown physics preset 'snooker'"),
    ("noise", "POST", "/api/shot", {**GOOD, "noise": "loud"}, 422, "unknown noise preset 'loud'"),
    ("malformed", "POST", "/api/shot", b'{"positions": [[0.1, ', 400, "malformed JSON"),
    ("agent-code", "POST", "/api/agent", {"positions": RACK, "agent": "tests/web/test_web.py:GOOD"}, 422, "unknown agent"),
    ("agent-league", "POST", "/api/agent", {"positions": RACK, "agent": "league:nobody"}, 422, "unknown agent"),
    ("agent-table", "POST", "/api/agent", {"positions": [[0.0, 0.0], *RACK[1:]], "agent": "random"}, 422, "off the table"),
    ("opponent", "POST", "/api/match", {"opponent": "nobody"}, 422, "no league player"),
    ("target", "POST", "/api/match", {"opponent": "random", "target": 0}, 422, "target"),
    ("no-match", "POST", "/api/match/abc/shot", {"action": [1.0, 0.5, 0.0, 0.0], "turn": 0}, 404, "no match"),
    ("no-turn", "POST", "/api/match/abc/shot", {"action": [1.0, 0.5, 0.0, 0.0]}, 422, "turn: Field required"),
    ("turn-negative", "POST", "/api/match/abc/shot", {"action": [1.0, 0.5, 0.0, 0.0], "turn": -1}, 422, "turn"),
    ("start-key", "POST", "/api/match", {"opponent": "random", "key": "../x"}, 422, "key"),
    ("dotdot", "GET", "/api/run?path=results/../pyproject.toml", None, 403, "'..'"),
    ("absolute", "GET", "/api/run?path=/etc/passwd", None, 403, "outside"),
    ("repo-file", "GET", "/api/run?path=pyproject.toml", None, 403, "outside"),
    ("missing", "GET", "/api/run?path=results/no_such_run", None, 404, "no run"),
    ("not-a-run", "GET", "/api/run?path=results/README.md", None, 404, "not a run"),
    ("considered-two", "POST", "/api/considered", {"positions": RACK, "run": P3_RUN, "agent": "random"}, 422, "either run"),
    ("considered-none", "POST", "/api/considered", {"positions": RACK}, 422, "either run"),
    ("considered-outside", "POST", "/api/considered", {"positions": RACK, "run": "/etc"}, 403, "outside"),
    ("considered-league", "POST", "/api/considered", {"positions": RACK, "run": "results/sagu/fastfiz_x5_run"}, 404,
     "not a run whose agent"),
    ("considered-table", "POST", "/api/considered", {"positions": [RACK[0], RACK[0], *RACK[2:]], "run": P3_RUN}, 422, "overlaps"),
    ("considered-action", "POST", "/api/considered", {"positions": RACK, "run": P3_RUN, "commanded": [1.0, 2.0, 0.0, 0.0]},
     422, "power p"),
    ("unit-missing", "GET", f"/api/run?path={SCORECARDS}/p3-exact-v1/nearest&unit=99", None, 404, "no chain 99"),
    ("p1-inning-missing", "GET", f"/api/run?path={P1_RUN}&unit=20", None, 404, "innings 0..19"),
]


@pytest.mark.parametrize("method,url,body,status,words", [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_input_is_a_4xx_with_a_message_and_the_server_goes_on(client, method, url, body, status, words):
    if isinstance(body, bytes):
        r = client.request(method, url, content=body, headers={"content-type": "application/json"})
    else:
        r = client.request(method, url, json=body)
    assert r.status_code == status, r.text
    assert words in r.json()["error"], r.json()
    assert client.post("/api/shot", json=GOOD).status_code == 200


def test_a_symlink_out_of_a_run_directory_is_refused(client, extra_runs):
    r = client.get("/api/run", params={"path": str(extra_runs / "out")})
    assert r.status_code == 403 and "symlink" in r.json()["error"]
    assert str(extra_runs) in client.get("/api/runs").json()["folders"]


# ----------------------------------------------------------------------------- hosts, origins, one error shape

OTHER_HOSTS = ["evil.example", "evil.example:8000", "localhost.evil.example", "127.0.0.1.nip.io:80", "localhost@evil.example",
               "127.0.0.2", "[::2]:80", "testserver", "localhost:80:80", ""]
OWN_HOSTS = ["localhost", "localhost:8000", "LocalHost:51234", "127.0.0.1", "127.0.0.1:80", "[::1]", "[::1]:8000", "[0:0::1]:9"]


def _only_error(r, status: int, *words: str) -> str:
    """The answer is ``status`` with the viewer's one error shape, a sentence holding ``words``."""
    assert r.status_code == status, r.text
    assert r.headers["content-type"] == "application/json", r.headers
    body = r.json()
    assert list(body) == ["error"] and isinstance(body["error"], str) and body["error"], body
    for w in words:
        assert w in body["error"], body
    assert "Traceback" not in r.text and "{'" not in body["error"], body  # a sentence: no traceback, no raw dict
    return body["error"]


@pytest.mark.parametrize("host", OTHER_HOSTS)
def test_another_host_is_refused_on_every_route(client, host):
    """DNS rebinding: another site's page whose name now points here sends its own name as the Host."""
    for method, url in [("GET", "/api/runs"), ("GET", "/"), ("GET", "/static/app.js"), ("GET", "/api/config"), ("GET", "/no/such/page"),
                        ("GET", f"/api/run?path={P3_RUN}"), ("POST", "/api/shot")]:
        r = client.request(method, url, headers={"host": host}, json=GOOD if method == "POST" else None)
        _only_error(r, 421, "is not one of this viewer's names", "DNS rebinding", "--allow-host")
    assert client.get("/api/config").status_code == 200  # the viewer's own name still passes


def test_a_match_is_not_started_for_another_host(client):
    matches = client.app.state.matches
    before = len(matches.sessions)
    r = client.post("/api/match", json={"opponent": "random", "target": 1}, headers={"host": "evil.example:8000"})
    _only_error(r, 421, "'evil.example:8000'")
    assert len(matches.sessions) == before


@pytest.mark.parametrize("host", OWN_HOSTS)
def test_the_viewer_s_own_names_pass_on_any_port(client, host):
    r = client.get("/api/config", headers={"host": host})
    assert r.status_code == 200 and r.json()["agents"], r.text
    page = client.get("/", headers={"host": host})
    assert page.status_code == 200 and b"/static/app.js" in page.content
    assert client.get("/static/style.css", headers={"host": host}).status_code == 200


def test_the_bind_address_and_allowed_names_pass_and_no_other(out_dir):
    c = viewer(create_app(out_dir=out_dir, hosts=["192.168.1.5", "Viewer.LAN", "[fe80::1]", "::"]))
    for host in ["192.168.1.5:8000", "viewer.lan", "VIEWER.lan:1", "[fe80::1]:8000", "[::]:80", "localhost", "[::1]"]:
        assert c.get("/api/config", headers={"host": host}).status_code == 200, host
    for host in ["192.168.1.6", "other.lan", "viewer.lan.evil.example", "[fe80::2]"]:
        _only_error(c.get("/api/config", headers={"host": host}), 421, "192.168.1.5, viewer.lan, [fe80::1], [::]")
    for bad in ["viewer.lan:8000", "a b", "", "http://viewer.lan", "[::1]:80", "fe80::1%eth0"]:
        with pytest.raises(ValueError, match="not a host name or address"):
            create_app(out_dir=out_dir, hosts=[bad])


def test_python_m_billiards_web_refuses_an_allowed_host_that_is_not_one():
    from billiards.web.__main__ import main

    with pytest.raises(SystemExit) as exit_:
        main(["--allow-host", "viewer.lan:8000"])
    assert exit_.value.code == 2


CROSS = [  # headers a browser sends with a write from another origin or site
    {"origin": "http://evil.example"},
    {"origin": "http://evil.example:80"},
    {"origin": "http://localhost:8001"},  # another local app, another port
    {"origin": "https://localhost"},  # another scheme
    {"origin": "http://127.0.0.1"},  # another of the viewer's names is another origin
    {"origin": "null"},  # a sandboxed frame, a file:// page
    {"origin": "http://localhost@evil.example"},
    {"referer": "http://evil.example/page.html"},
    {"sec-fetch-site": "cross-site"},
    {"sec-fetch-site": "same-site"},
    {"origin": "http://localhost", "sec-fetch-site": "cross-site"},
]


@pytest.mark.parametrize("headers", CROSS, ids=[",".join(f"{k}={v}" for k, v in h.items()) for h in CROSS])
def test_a_cross_origin_write_is_refused_and_starts_nothing(client, headers):
    matches = client.app.state.matches
    before = len(matches.sessions)
    r = client.post("/api/match", json={"opponent": "random", "target": 1}, headers=headers)
    _only_error(r, 403, "is refused: only the viewer's own page (http://localhost)")
    assert len(matches.sessions) == before
    _only_error(client.post("/api/shot", json=GOOD, headers=headers), 403, "from another")
    _only_error(client.put("/api/shot", json=GOOD, headers=headers), 403)
    _only_error(client.delete("/api/match/abc", headers=headers), 403)


SAME = [
    {"origin": "http://localhost", "sec-fetch-site": "same-origin"},
    {"origin": "http://localhost:80"},
    {"referer": "http://localhost/", "sec-fetch-site": "same-origin"},
    {"sec-fetch-site": "none"},
    {},  # no browser: curl, a script
]


@pytest.mark.parametrize("headers", SAME, ids=[",".join(f"{k}={v}" for k, v in h.items()) or "none" for h in SAME])
def test_a_same_origin_write_or_one_without_a_browser_passes(client, headers):
    assert client.post("/api/shot", json=GOOD, headers=headers).status_code == 200
    r = client.post("/api/match", json={"opponent": "random", "target": 1}, headers=headers)
    assert r.status_code == 200, r.text


def test_the_origin_is_compared_with_the_host_the_browser_used(client):
    """Reached as 127.0.0.1:8000 (or through a tunnel on another port), the page's own origin is that one."""
    h = {"host": "127.0.0.1:8000", "origin": "http://127.0.0.1:8000", "sec-fetch-site": "same-origin"}
    assert client.post("/api/shot", json=GOOD, headers=h).status_code == 200
    _only_error(client.post("/api/shot", json=GOOD, headers={**h, "origin": "http://localhost:8000"}), 403, "'http://localhost:8000'")
    h6 = {"host": "[::1]:9", "origin": "http://[::1]:9"}
    assert client.post("/api/shot", json=GOOD, headers=h6).status_code == 200


def test_a_cross_origin_read_gets_no_cors_header(client):
    """Reads are not refused by origin: the browser keeps another origin's page from reading them, and no
    Access-Control-Allow-Origin header lets it."""
    r = client.get("/api/runs", headers={"origin": "http://evil.example"})
    assert r.status_code == 200 and not any(k.lower().startswith("access-control") for k in r.headers)


def test_every_error_has_one_shape(client):
    _only_error(client.get("/no/such/page"), 404, "no page or endpoint GET '/no/such/page'")
    _only_error(client.post("/api/runs"), 405, "'/api/runs' does not take POST (it takes GET)")
    _only_error(client.get("/api/run", params={"path": "results/no_such_run"}), 404, "no run")
    _only_error(client.get("/static/nothing.js"), 404, "no static file")
    _only_error(client.get("/api/match/nothing"), 404, "no match 'nothing'")
    _only_error(client.get("/api/run"), 422, "query.path: Field required")
    _only_error(client.get("/api/run", params={"path": P3_RUN, "unit": -1}), 422, "query.unit")
    _only_error(client.post("/api/shot", json={"positions": RACK}), 422, "action: Field required")
    _only_error(client.post("/api/shot", content=b"[", headers={"content-type": "application/json"}), 400, "malformed JSON")


def test_a_shot_in_a_match_that_is_over_is_409_with_a_sentence(client):
    start = client.post("/api/match", json={"opponent": "random", "target": 1, "seed": 2})
    assert start.status_code == 200, start.text
    state = start.json()["state"]
    client.app.state.matches.get(state["id"]).over = True  # ended (the full match is test_a_match_against_random_...)
    r = client.post(f"/api/match/{state['id']}/shot", json={"action": [1.0, 0.5, 0.0, 0.0], "turn": 0})
    scores = ", ".join(f"{who} {n:g}" for who, n in state["scores"].items())
    _only_error(r, 409, f"match {state['id']} is over ({scores}); start another")


def test_a_bug_is_a_500_with_a_generic_sentence_logged_with_its_traceback(client, monkeypatch, caplog):
    from billiards.web.guard import BUG

    def broken():
        raise RuntimeError("secret detail /srv/someone/.ssh")

    monkeypatch.setattr(client.app.state.store, "list_runs", broken)
    with caplog.at_level("ERROR", logger="billiards.web"):
        r = client.get("/api/runs")
    assert _only_error(r, 500) == BUG
    assert "secret" not in r.text and "RuntimeError" not in r.text
    logged = [rec for rec in caplog.records if rec.name == "billiards.web" and rec.exc_info]
    assert logged and "GET /api/runs" in logged[0].getMessage() and "secret detail" in str(logged[0].exc_info[1])
    monkeypatch.undo()
    assert client.get("/api/runs").status_code == 200 and client.post("/api/shot", json=GOOD).status_code == 200


# ----------------------------------------------------------------------------- agents


def test_agents_random_and_nearest_answer(client):
    from billiards import domain

    a = client.post("/api/agent", json={"positions": RACK, "agent": "random", "seed": 3}).json()
    b = client.post("/api/agent", json={"positions": RACK, "agent": "random", "seed": 3}).json()
    c = client.post("/api/agent", json={"positions": RACK, "agent": "random", "seed": 4}).json()
    assert a["action"] == b["action"] != c["action"] and a["considered"] is None
    n = client.post("/api/agent", json={"positions": RACK, "agent": "nearest", "noise": "fastfiz", "replays": 20}).json()
    theta = float(domain.aim_window(np.array(RACK)[None], get_params().ball_radius)[0].reshape(-1)[0])
    assert n["action"] == [theta, 0.5, 0.0, 0.0]
    assert n["noisy"]["n"] == 20 and len(n["noisy"]["white_ends"]) == 20
    assert "search:h2" in client.get("/api/config").json()["agents"]


# ----------------------------------------------------------------------------- runs


def test_runs_list_a_committed_p3_run_and_its_shots_replay_exactly(client):
    runs = {r["path"]: r for r in client.get("/api/runs").json()["runs"]}
    assert runs[P3_RUN]["kind"] == "p3" and runs[P3_RUN]["replayable"]
    assert any(r["kind"] == "league" for r in runs.values()) and any(r["kind"] == "scorecard" for r in runs.values())
    run = client.get("/api/run", params={"path": P3_RUN}).json()
    assert run["physics"] == "korean_medium" and len(run["units"]) == 20
    records = {json.loads(line)["seed"]: json.loads(line) for line in (ROOT / P3_RUN / "chains.jsonl").read_text().splitlines()}
    chain = run["units"][0]
    assert [s["positions"] for s in chain["shots"]] == [s[0] for s in records[chain["id"]]["last_shots"]]
    for shot, nxt in zip(chain["shots"], chain["shots"][1:] + [None]):
        r = client.post("/api/shot", json={"positions": shot["positions"], "action": shot["played"], "paths": False}).json()
        assert r["result"]["score"] == shot["scored"]
        if nxt is not None:
            assert r["final"] == nxt["positions"]  # the chain's next table, bit for bit


@pytest.mark.slow
def test_every_committed_p3_shot_replays_onto_the_next_recorded_table(client):
    """Through the viewer's loader, every recorded shot of every committed P3 run (the played
    shot, on its run's table) scores as recorded and ends exactly on the chain's next table."""
    from billiards.web.runs import RunStore

    store, checked = RunStore(), 0
    for entry in store.list_runs():
        if entry["kind"] != "p3" or not entry["path"].startswith("results/"):
            continue
        run = store.load(entry["path"])
        assert run["replayable"], entry["path"]
        params = get_params(run["physics"])
        for unit in run["units"]:
            shots = unit["shots"]
            for shot, nxt in zip(shots, shots[1:] + [None]):
                res = simulate_shot(np.array(shot["positions"]), np.array(shot["played"]), params)
                assert res.score == shot["scored"], (entry["path"], unit["id"])
                if nxt is not None:
                    assert res.positions.tolist() == nxt["positions"], (entry["path"], unit["id"])
                checked += 1
    assert checked > 10_000


@pytest.mark.slow
def test_a_league_match_is_played_again_with_its_recorded_scores(client):
    r = client.get("/api/run", params={"path": "results/sagu/fastfiz_x5_run", "unit": 0})
    assert r.status_code == 200, r.text
    unit = r.json()["units"][0]
    assert unit["reproduced"] and unit["replayed_scores"] == unit["record"]["scores"]
    assert unit["shots"][-1]["scores"] == [unit["record"]["scores"]["white"], unit["record"]["scores"]["yellow"]]


def _replays_onto_each_other(client, shots, physics="korean_medium"):
    """Every shot, played again exactly from its played action, scores as recorded and ends on
    the next shot's table."""
    for shot, nxt in zip(shots, shots[1:] + [None]):
        r = client.post("/api/shot", json={"positions": shot["positions"], "action": shot["played"], "physics": physics,
                                           "shooter": shot["shooter"], "paths": False})
        assert r.status_code == 200, r.text
        assert r.json()["result"]["score"] == shot["scored"]
        if nxt is not None:
            assert r.json()["final"] == nxt["positions"]


def test_runs_list_every_kind_the_viewer_replays(client):
    runs = {r["path"]: r for r in client.get("/api/runs").json()["runs"]}
    card = runs[f"{SCORECARDS}/p3-exact-v1/nearest"]
    assert card["kind"] == "scorecard" and card["replayable"] and card["units"] == 20 and card["agent"] == "nearest"
    assert runs[P1_RUN]["kind"] == "p1" and runs[P1_RUN]["replayable"] and runs[P1_RUN]["units"] == 20
    shipped = runs["results/training/noisy/aim_features_fastfiz/seed0"]
    assert shipped["kind"] == "training" and shipped["replayable"] and shipped["policy"] == "results/policies/fastfiz_aim_features/seed0.pt"
    unshipped = runs["results/training/table4/aim_s0"]
    assert unshipped["kind"] == "training" and not unshipped["replayable"] and "no weights of this run were shipped" in unshipped["why_not"]
    code = next(r for p, r in runs.items() if p.endswith("code_scorecard"))
    assert not code["replayable"] and "names code to import" in code["why_not"]
    big = runs["results/search/paper/table6/geometric/puct_p1"]  # 100 x 100 shots: under the cap, listed as replayable
    assert big["kind"] == "p1" and big["replayable"]


@pytest.mark.parametrize("run,unit", [(f"{SCORECARDS}/p3-exact-v1/nearest", 4), (f"{SCORECARDS}/p1-exact-v1/random", 57)])
def test_a_scorecard_unit_is_played_again_with_the_ledger_s_scores(client, run, unit):
    listing = client.get("/api/run", params={"path": run}).json()
    assert listing["kind"] == "scorecard" and listing["replayable"] and not listing["considers"]
    assert all(u["shots"] is None for u in listing["units"])
    r = client.get("/api/run", params={"path": run, "unit": unit})
    assert r.status_code == 200, r.text
    got = r.json()["units"][0]
    assert got["matches_ledger"] is True and got["differences"] == [] and "gives the ledger's record" in got["check"]
    assert got["replayed"] == got["record"]  # the inning's points, or the chain's length and how it ended
    if "points" in got["record"]:
        assert len(got["shots"]) == 20 and sum(s["scored"] for s in got["shots"]) == got["record"]["points"]
    else:
        assert len(got["shots"]) == got["record"]["length"] + 1
    _replays_onto_each_other(client, got["shots"])


def test_a_scorecard_whose_agent_names_code_is_refused(client, extra_runs):
    path = str(extra_runs / "code_scorecard")
    listing = client.get("/api/run", params={"path": path}).json()
    assert not listing["replayable"] and CODE_SPEC in listing["note"] and "never imports code" in listing["note"]
    assert len(listing["units"]) == 100  # its innings are listed, with their recorded points
    r = client.get("/api/run", params={"path": path, "unit": 0})
    assert r.status_code == 422 and "cannot be played again" in r.json()["error"] and CODE_SPEC in r.json()["error"]
    r = client.post("/api/considered", json={"positions": RACK, "run": path})
    assert r.status_code == 422 and "names code" in r.json()["error"]
    assert client.post("/api/shot", json=GOOD).status_code == 200


@pytest.mark.slow
def test_a_p1_search_run_is_played_again_with_its_points_per_inning(client):
    recorded = json.loads((ROOT / P1_RUN / "results.json").read_text())["values"]
    r = client.get("/api/run", params={"path": P1_RUN, "unit": 3})
    assert r.status_code == 200, r.text
    inning = r.json()["units"][0]
    assert inning["matches_record"] is True and "every inning's points equal results.json's" in inning["check"]
    assert inning["replayed"]["points"] == inning["record"]["points"] == recorded[3]
    assert len(inning["shots"]) == 50 and any(s["noisy"] for s in inning["shots"])
    _replays_onto_each_other(client, inning["shots"])
    again = client.get("/api/run", params={"path": P1_RUN, "unit": 7}).json()["units"][0]  # the same replay, kept
    assert again["replayed"]["points"] == recorded[7] and again["shots"][0]["caption"].startswith("inning 7,")


def test_a_training_evaluation_is_played_again_with_its_shipped_policy(tmp_path):
    """A training run whose weights are shipped (a policy under results/policies whose source
    is the run) plays its evaluation again; its points equal eval.json's. The run here is made
    in a repository copy of its own: a shipped policy re-sealed with that run as its source, the
    run's eval.json written by billiards.evaluation.evaluate_policy (the committed runs' eval.json were
    written by older code: docs/reproducibility.md)."""
    from billiards.evaluation import evaluate_policy
    from billiards.files import SEAL_KEY, load_tagged, save_tagged
    from billiards.physics.config import params_from_config
    from billiards.physics.noise import noise_from_config
    from billiards.rl.checkpoint import CheckpointError
    from billiards.rl.policy import POLICY_FORMAT, load_policy

    root, name = tmp_path / "repo", "results/training/tiny/seed0"
    run = root / name
    run.mkdir(parents=True)
    shipped = ROOT / "results/policies/fastfiz_aim_features/seed0.pt"
    payload = load_tagged(shipped, POLICY_FORMAT, CheckpointError, "exported policy")
    payload = {k: v for k, v in payload.items() if k != SEAL_KEY}
    save_tagged(root / "results/policies/tiny/seed0.pt", {**payload, "source": name})
    (run / "config.yaml").write_bytes((ROOT / "results/training/noisy/aim_features_fastfiz/seed0/config.yaml").read_bytes())
    policy, cfg = load_policy(shipped)
    evaluate_policy(policy, n_innings=12, max_shots=6, seed=5, constrain_aim=cfg.env.constrain_aim, extra_features=cfg.env.extra_features,
             env_kwargs=dict(params=params_from_config(cfg.physics)), noise=noise_from_config(cfg.get("noise"))).to_json(run / "eval.json")
    recorded = json.loads((run / "eval.json").read_text())["points"]
    client = viewer(create_app(out_dir=None, root=root))
    listed = {r["path"]: r for r in client.get("/api/runs").json()["runs"]}
    assert listed[name]["replayable"] and listed[name]["policy"] == "results/policies/tiny/seed0.pt"
    r = client.get("/api/run", params={"path": name, "unit": 4})
    assert r.status_code == 200, r.text
    inning = r.json()["units"][0]
    assert inning["matches_record"] is True and inning["replayed"]["points"] == recorded[4] and len(inning["shots"]) == 6
    _replays_onto_each_other(client, inning["shots"])


def test_a_committed_training_run_with_shipped_weights_is_played_again(client):
    """The committed noisy run's evaluation plays again; the answer says whether today's code
    gives eval.json's points (it does not: that eval.json was written by older code), and a run
    without shipped weights is refused with the sentence that says so."""
    path = "results/training/noisy/aim_features_fastfiz/seed0"
    inning = client.get("/api/run", params={"path": path, "unit": 0}).json()["units"][0]
    assert isinstance(inning["matches_record"], bool) and inning["check"].startswith("played again")
    assert len(inning["shots"]) == 10 and all(s["noisy"] for s in inning["shots"])
    _replays_onto_each_other(client, inning["shots"])
    r = client.get("/api/run", params={"path": "results/training/table4/aim_s0", "unit": 0})
    assert r.status_code == 422 and "no weights of this run were shipped" in r.json()["error"]


def test_what_a_search_considered_for_a_recorded_shot(client):
    run = client.get("/api/run", params={"path": P3_RUN}).json()
    assert run["considers"]
    chain = run["units"][0]
    shot = chain["shots"][0]
    r = client.post("/api/considered", json={"run": P3_RUN, "positions": shot["positions"], "commanded": shot["commanded"],
                                             "seed": chain["seed"]})
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["recorded"] == shot["commanded"] and isinstance(out["same_choice"], bool) and out["noisy"] is None  # exact play
    cands = out["considered"]["candidates"]
    assert cands["count"] >= len(cands["top"]) > 0 and out["considered"]["sims"] == 400
    assert all(len(c["action"]) == 4 and isinstance(c["score"], bool) for c in cands["top"])
    again = client.post("/api/considered", json={"run": P3_RUN, "positions": shot["positions"], "commanded": shot["commanded"],
                                                 "seed": chain["seed"]}).json()
    assert again["action"] == out["action"]  # reseeded: the same answer


def test_what_the_position_aware_search_considered_under_noise(client):
    run = client.get("/api/run", params={"path": NOISY_P3}).json()
    chain = run["units"][0]
    shot = chain["shots"][-2]
    r = client.post("/api/considered", json={"run": NOISY_P3, "positions": shot["positions"], "commanded": shot["commanded"],
                                             "seed": chain["seed"], "replays": 40})
    assert r.status_code == 200, r.text
    noisy, leave = r.json()["noisy"], r.json()["noisy"]["leave"]
    assert noisy["n"] == len(noisy["white_ends"]) == len(leave["values"]) == 40 and r.json()["noise"] == "fastfiz"
    assert leave["position"] == 8.0 and all(0 < v < 1 for v in leave["values"])
    assert (leave["mean_if_scored"] is None) == (not any(noisy["scored"]))


def test_what_a_scorecard_s_search_agent_considers(client):
    run = f"{SCORECARDS}/p3-exact-v1/h2_geometric"
    assert client.get("/api/run", params={"path": run}).json()["considers"]
    r = client.post("/api/considered", json={"run": run, "positions": RACK, "seed": 7300000})
    assert r.status_code == 200, r.text
    assert r.json()["recorded"] is None and r.json()["considered"]["candidates"]["top"]


@pytest.mark.slow
def test_a_match_track_scorecard_unit_is_played_again_with_the_ledger_s_scores(client):
    r = client.get("/api/run", params={"path": f"{SCORECARDS}/match-x5-v1/random", "unit": 11})
    assert r.status_code == 200, r.text
    match = r.json()["units"][0]
    assert match["matches_ledger"] is True and match["replayed"] == match["record"]
    last = match["shots"][-1]
    assert last["scores"] == match["record"]["points"] and {s["agent_shot"] for s in match["shots"]} == {True, False}
    _replays_onto_each_other(client, match["shots"][:1])


# ----------------------------------------------------------------------------- a match


def test_a_match_against_random_to_one_point_plays_to_its_end_and_is_saved(client, out_dir):
    start = client.post("/api/match", json={"opponent": "random", "noise": "none", "target": 1, "seed": 5})
    assert start.status_code == 200, start.text
    state = start.json()["state"]
    assert state["to_play"] == "human" and state["positions"] == RACK
    for _ in range(20):
        if state["over"]:
            break
        hint = client.post("/api/agent", json={"positions": state["positions"], "agent": "search:h2"}).json()
        r = client.post(f"/api/match/{state['id']}/shot", json={"action": hint["action"], "turn": state["turn"]})
        assert r.status_code == 200, r.text
        shots, state = r.json()["shots"], r.json()["state"]
        assert shots[0]["who"] == "human" and all(s["paths"]["xy"] for s in shots)
        for s in shots:  # every shot of the match is the simulator's, from its shooter's view
            res = simulate_shot(shooter_view(np.array(s["positions"]), s["shooter"]), np.array(s["played"]))
            assert shooter_view(res.positions, s["shooter"]).tolist() == s["final"]
    assert state["over"] and max(state["scores"].values()) == 1
    assert client.post(f"/api/match/{state['id']}/shot", json={"action": [1.0, 0.5, 0.0, 0.0], "turn": state["turn"]}).status_code == 409
    saved = Path(state["saved"]) if Path(state["saved"]).is_absolute() else ROOT / state["saved"]
    assert saved.is_relative_to(out_dir)
    problems, _ = verify(saved)
    assert problems == []
    listed = [r for r in client.get("/api/runs").json()["runs"] if r["kind"] == "web"]
    assert listed
    run = client.get("/api/run", params={"path": listed[0]["path"]}).json()
    assert run["kind"] == "web" and run["units"][0]["shots"][-1]["scores"] == [state["scores"]["human"], state["scores"]["random"]]


def _ledger(folder: Path) -> list[dict]:
    return [json.loads(line) for line in (folder / "shots.jsonl").read_text().splitlines() if line.strip()]


def _folder(out_dir: Path, match_id: str) -> Path:
    return out_dir / "matches" / match_id


def _start(client, **settings) -> dict:
    r = client.post("/api/match", json={"opponent": "random", "noise": "fastfiz_x5", "target": 5, "seed": 3, **settings})
    assert r.status_code == 200, r.text
    return r.json()["state"]


def _shoot(client, state: dict, action, turn: int | None = None):
    return client.post(f"/api/match/{state['id']}/shot", json={"action": action, "turn": state["turn"] if turn is None else turn})


SHOTS = [[1.0, 0.55, 0.1, 0.0], [2.2, 0.7, -0.2, 0.3], [4.0, 0.45, 0.0, -0.4], [0.3, 0.9, 0.5, 0.5], [5.5, 0.6, 0.0, 0.0]]


def test_a_shot_names_its_turn_and_a_stale_or_repeated_one_is_refused(client, out_dir):
    state = _start(client)
    assert state["turn"] == 0 and state["to_play"] == "human"
    folder = _folder(out_dir, state["id"])
    r = _shoot(client, state, SHOTS[0])
    assert r.status_code == 200, r.text
    after = r.json()["state"]
    assert after["turn"] == len(r.json()["shots"]) and [s["turn"] for s in r.json()["shots"]] == list(range(after["turn"]))
    lines = (folder / "shots.jsonl").read_bytes()
    again = _shoot(client, state, SHOTS[0])  # the same request again: a second click, a retry
    _only_error(again, 409, f"turn 0 of match {state['id']} was played already: the match is at turn {after['turn']}")
    _only_error(_shoot(client, after, SHOTS[1], turn=after["turn"] + 1), 409, "has not come")
    assert (folder / "shots.jsonl").read_bytes() == lines  # nothing played, nothing written
    assert client.get(f"/api/match/{state['id']}").json()["state"] == after


def test_identical_shot_requests_sent_at_once_play_once(client, out_dir):
    state = _start(client, seed=4)
    barrier, answers = threading.Barrier(4), []

    def send():
        barrier.wait()
        answers.append(_shoot(client, state, SHOTS[1]))

    threads = [threading.Thread(target=send) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(600)
    assert sorted(a.status_code for a in answers) == [200, 409, 409, 409]
    played = next(a for a in answers if a.status_code == 200).json()
    records = _ledger(_folder(out_dir, state["id"]))
    assert [r["who"] for r in records].count("human") == 1 and len(records) == played["state"]["turn"]
    assert all("was played already" in a.json()["error"] for a in answers if a.status_code == 409)


def test_a_start_repeated_with_its_key_starts_one_match(client, out_dir):
    before = set(p.name for p in (out_dir / "matches").iterdir()) if (out_dir / "matches").is_dir() else set()
    body = {"opponent": "random", "noise": "none", "target": 2, "seed": 8, "key": "page-start-0001"}
    answers = [client.post("/api/match", json=body).json() for _ in range(3)]
    assert len({a["state"]["id"] for a in answers}) == 1 and [a["repeated"] for a in answers] == [False, True, True]
    assert set(p.name for p in (out_dir / "matches").iterdir()) - before == {answers[0]["state"]["id"]}
    other = client.post("/api/match", json={**body, "key": "page-start-0002"}).json()
    assert other["state"]["id"] != answers[0]["state"]["id"]


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_a_match_is_on_disk_from_its_start_and_a_restarted_server_plays_on_as_if_none_had_been(out_dir):
    """Two matches of the same settings and shots: one played straight through, the other read
    back by a new app over the same folder between its shots; they end on the same table with
    the same scores (the noise's generator and the league player's seeds come from the ledger)."""
    settings = {"opponent": "random", "noise": "fastfiz_x5", "target": 10, "seed": 21}
    first = viewer(create_app(out_dir=out_dir))
    straight, resumed = _start(first, **settings), _start(first, **settings)
    for state in (straight, resumed):  # on disk before any shot: verify accepts the folder
        folder = _folder(out_dir, state["id"])
        assert sorted(p.name for p in folder.iterdir()) == ["match.json", "shots.jsonl"]
        assert verify(folder) == ([], [f"{display_path(folder / 'shots.jsonl')}: 0 sealed records"])
    for k, action in enumerate(SHOTS):
        r = _shoot(first, straight, action)
        assert r.status_code == 200, r.text
        straight = r.json()["state"]
    for k, action in enumerate(SHOTS):
        client = viewer(create_app(out_dir=out_dir))  # a server restart before every shot
        got = client.get(f"/api/match/{resumed['id']}")
        assert got.status_code == 200, got.text
        assert got.json()["state"] == resumed
        r = _shoot(client, resumed, action)
        assert r.status_code == 200, r.text
        resumed = r.json()["state"]
    same = ("positions", "scores", "turn", "innings", "to_play", "over")
    assert {k: resumed[k] for k in same} == {k: straight[k] for k in same}
    assert [r["final"] for r in _ledger(_folder(out_dir, resumed["id"]))] == [r["final"] for r in _ledger(_folder(out_dir, straight["id"]))]
    folder = _folder(out_dir, resumed["id"])  # abandoned here, unfinished: saved and verifiable as it stands
    problems, notes = verify(folder)
    assert problems == [] and f"{len(_ledger(folder))} sealed records" in notes[0]
    summary = json.loads((folder / "match.json").read_text())
    assert summary["turn"] == resumed["turn"] and summary["over"] is False and summary["settings"]["seed"] == 21
    listed = {m["id"]: m for m in viewer(create_app(out_dir=out_dir)).get("/api/matches").json()["matches"]}
    assert listed[resumed["id"]]["turn"] == resumed["turn"] and listed[resumed["id"]]["over"] is False


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_python_m_billiards_files_verify_accepts_an_unfinished_match(client, out_dir):
    from billiards import files

    if "billiards.web.match:SHOTS" not in files.LEDGER_PROVIDERS:
        pytest.skip("billiards.files.LEDGER_PROVIDERS does not name billiards.web.match:SHOTS: the verify command does not "
                    "know the viewer's match ledger (shots.jsonl) yet")
    state = _start(client, seed=30)
    _shoot(client, state, SHOTS[0])
    from conftest import app_here

    out = app_here("billiards.files", "verify", str(_folder(out_dir, state["id"])), cwd=ROOT)
    assert out.returncode == 0 and "ledger and summary agree" in out.stdout, out.stdout + out.stderr


def test_a_damaged_ledger_is_refused_and_a_torn_line_is_cut(out_dir):
    client = viewer(create_app(out_dir=out_dir))
    state = _start(client, seed=40)
    state = _shoot(client, state, SHOTS[2]).json()["state"]
    folder = _folder(out_dir, state["id"])
    ledger = folder / "shots.jsonl"
    whole = ledger.read_bytes()
    ledger.write_bytes(whole + b'{"turn": 99, "who"')  # a kill mid-append
    restarted = viewer(create_app(out_dir=out_dir))
    got = restarted.get(f"/api/match/{state['id']}")
    assert got.status_code == 200 and got.json()["state"] == state and ledger.read_bytes() == whole
    ledger.write_bytes(whole.replace(b'"scored": false', b'"scored": true', 1))  # an edited record
    _only_error(viewer(create_app(out_dir=out_dir)).get(f"/api/match/{state['id']}"), 422,
                f"match {state['id']} cannot be resumed: ")
    problems, _ = verify(folder)
    assert problems and "does not match its seal" in problems[0]


def test_a_match_played_on_by_another_server_is_refused_here_and_read_again(out_dir):
    one, two = viewer(create_app(out_dir=out_dir)), viewer(create_app(out_dir=out_dir))
    state = _start(one, seed=50)
    assert two.get(f"/api/match/{state['id']}").json()["state"] == state
    played = _shoot(two, state, SHOTS[3]).json()["state"]
    _only_error(_shoot(one, state, SHOTS[4]), 409, "was played on elsewhere")
    assert one.get(f"/api/match/{state['id']}").json()["state"] == played  # read back from the folder
    assert _shoot(one, played, SHOTS[4]).status_code == 200


def test_the_page_is_told_whether_the_simulator_is_being_prepared(monkeypatch):
    import billiards.physics.warmup as warmup

    compiling, done = threading.Event(), threading.Event()

    def slow_warm_up(log=print):
        compiling.set()
        done.wait(600)
        return 42.0

    monkeypatch.setattr(warmup, "kernels_cached", lambda: False)
    monkeypatch.setattr(warmup, "warm_up", slow_warm_up)
    client = viewer(create_app(out_dir=None))
    assert compiling.wait(600)
    r = client.get("/api/simulator").json()
    assert r["cached"] is False and r["ready"] is False and r["expected_s"] == warmup.WARM_UP_SECONDS and r["error"] is None
    done.set()
    for _ in range(600):
        if client.get("/api/simulator").json()["ready"]:
            break
        time.sleep(0.05)
    assert client.get("/api/simulator").json() == {"cached": False, "ready": True, "expected_s": warmup.WARM_UP_SECONDS,
                                                   "elapsed_s": 42.0, "error": None}


# ----------------------------------------------------------------------------- the server process


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_slow_agent_does_not_block_a_shot(monkeypatch, out_dir):
    """The endpoints that compute run in the thread pool: a shot is answered while an agent thinks."""
    import uvicorn

    import billiards.web.catalogue as web_catalogue

    real_ask = web_catalogue.ask
    thinking, release = threading.Event(), threading.Event()

    def slow_ask(*args, **kwargs):  # an agent that thinks until the test lets it answer
        thinking.set()
        release.wait(600)
        return real_ask(*args, **kwargs)

    monkeypatch.setattr(web_catalogue, "ask", slow_ask)
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(create_app(out_dir=out_dir), host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        for _ in range(200):
            if server.started:
                break
            time.sleep(0.05)
        url = f"http://127.0.0.1:{port}"

        def post(path, body):
            req = urllib.request.Request(url + path, json.dumps(body).encode(), {"content-type": "application/json"})
            with urllib.request.urlopen(req, timeout=600) as resp:  # a limit against a hang only
                return json.loads(resp.read())

        slow = threading.Thread(target=post, args=("/api/agent", {"positions": RACK, "agent": "random"}))
        slow.start()
        assert thinking.wait(600), "the agent request never reached the agent"
        # answered while the agent is still held: had the shot waited for the agent, it would hang here
        assert post("/api/shot", GOOD)["final"]
        assert slow.is_alive() and not release.is_set()
        release.set()
        slow.join(600)
    finally:
        release.set()
        server.should_exit = True
        thread.join(10)


@pytest.mark.slow
def test_python_m_billiards_web_prints_its_url_and_serves(out_dir):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "billiards.web", "--port", "0", "--out", str(out_dir), "--allow-host", "viewer.test"],
                            cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline().strip()
        assert line.startswith("billiards viewer: http://127.0.0.1:"), line + proc.stderr.read()[-2000:] if not line else line
        url = line.split(": ", 1)[1]
        with urllib.request.urlopen(url + "api/config", timeout=600) as resp:
            assert "korean_medium" in json.loads(resp.read())["physics"]
        with urllib.request.urlopen(url, timeout=600) as resp:
            assert b"/static/app.js" in resp.read()
        port = url.rstrip("/").rsplit(":", 1)[1]
        with urllib.request.urlopen(urllib.request.Request(url, headers={"Host": f"viewer.test:{port}"}), timeout=600) as resp:
            assert resp.status == 200
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(urllib.request.Request(url + "api/runs", headers={"Host": f"evil.example:{port}"}), timeout=600)
        assert refused.value.code == 421 and "DNS rebinding" in json.loads(refused.value.read())["error"]
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(urllib.request.Request(url + "api/shot", json.dumps(GOOD).encode(), {
                "content-type": "application/json", "Origin": "http://evil.example"}), timeout=600)
        assert refused.value.code == 403
    finally:
        proc.terminate()
        proc.wait(30)


def test_the_run_listing_reads_through_the_one_reader_and_never_blocks_on_a_fifo(tmp_path):
    """A FIFO in place of a ledger or a summary in a run folder the viewer lists is refused unread
    (billiards.files' one reader): the listing answers, the run counts no units."""
    import os
    import threading

    from billiards.web.runs import RunStore

    run = tmp_path / "results" / "search" / "p3run"
    run.mkdir(parents=True)
    os.mkfifo(run / "chains.jsonl")
    (run / "config.yaml").write_text("seed: 0\n")
    listing = {}
    worker = threading.Thread(target=lambda: listing.update(runs=RunStore(root=tmp_path).list_runs()), daemon=True)
    worker.start()
    worker.join(timeout=300)  # only a guard against a hang (a FIFO read blocks forever)
    assert not worker.is_alive(), "a FIFO in a run folder blocked the viewer's listing"
    (entry,) = [r for r in listing["runs"] if r["path"].endswith("p3run")]
    assert entry["units"] == 0
