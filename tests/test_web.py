"""The viewer's JSON API (billiards.web) through FastAPI's TestClient: its shots are the
simulator's bit for bit, bad input is a 4xx with a message and the next request still
succeeds, agents answer, recorded runs list and replay exactly, paths outside the allowed
folders are refused, a match plays to its end and is saved as a league ledger."""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("httpx")  # FastAPI's TestClient
from fastapi.testclient import TestClient  # noqa: E402

from billiards.envs.sagu import shooter_view  # noqa: E402
from billiards.files import ROOT, verify  # noqa: E402
from billiards.physics import canonical_rack, get_params, simulate_shot  # noqa: E402
from billiards.physics.noise import get_noise  # noqa: E402
from billiards.web import create_app  # noqa: E402

P3_RUN = "results/search/paper/table6/geometric/h2_p3"  # a committed exact P3 run (20 chains, their last shots)
RACK = canonical_rack().tolist()
GOOD = {"positions": RACK, "action": [1.0, 0.6, 0.2, -0.1]}


@pytest.fixture(scope="module")
def extra_runs(tmp_path_factory):
    """A run directory given on the command line, holding a symlink that leads out of it."""
    d = tmp_path_factory.mktemp("runs")
    (d / "out").symlink_to(ROOT / "billiards")
    return d


@pytest.fixture(scope="module")
def out_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("web_out")


@pytest.fixture(scope="module")
def client(extra_runs, out_dir):
    return TestClient(create_app(run_dirs=[extra_runs], out_dir=out_dir))


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
    ("agent-code", "POST", "/api/agent", {"positions": RACK, "agent": "tests/test_web.py:GOOD"}, 422, "unknown agent"),
    ("agent-league", "POST", "/api/agent", {"positions": RACK, "agent": "league:nobody"}, 422, "unknown agent"),
    ("agent-table", "POST", "/api/agent", {"positions": [[0.0, 0.0], *RACK[1:]], "agent": "random"}, 422, "off the table"),
    ("opponent", "POST", "/api/match", {"opponent": "nobody"}, 422, "no league player"),
    ("target", "POST", "/api/match", {"opponent": "random", "target": 0}, 422, "target"),
    ("no-match", "POST", "/api/match/abc/shot", {"action": [1.0, 0.5, 0.0, 0.0]}, 404, "no match"),
    ("dotdot", "GET", "/api/run?path=results/../pyproject.toml", None, 403, "'..'"),
    ("absolute", "GET", "/api/run?path=/etc/passwd", None, 403, "outside"),
    ("repo-file", "GET", "/api/run?path=pyproject.toml", None, 403, "outside"),
    ("missing", "GET", "/api/run?path=results/no_such_run", None, 404, "no run"),
    ("not-a-run", "GET", "/api/run?path=results/README.md", None, 404, "not a run"),
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
        r = client.post(f"/api/match/{state['id']}/shot", json={"action": hint["action"]})
        assert r.status_code == 200, r.text
        shots, state = r.json()["shots"], r.json()["state"]
        assert shots[0]["who"] == "human" and all(s["paths"]["xy"] for s in shots)
        for s in shots:  # every shot of the match is the simulator's, from its shooter's view
            res = simulate_shot(shooter_view(np.array(s["positions"]), s["shooter"]), np.array(s["played"]))
            assert shooter_view(res.positions, s["shooter"]).tolist() == s["final"]
    assert state["over"] and max(state["scores"].values()) == 1
    assert client.post(f"/api/match/{state['id']}/shot", json={"action": [1.0, 0.5, 0.0, 0.0]}).status_code == 409
    saved = Path(state["saved"]) if Path(state["saved"]).is_absolute() else ROOT / state["saved"]
    assert saved.is_relative_to(out_dir)
    problems, _ = verify(saved)
    assert problems == []
    listed = [r for r in client.get("/api/runs").json()["runs"] if r["kind"] == "web"]
    assert listed
    run = client.get("/api/run", params={"path": listed[0]["path"]}).json()
    assert run["kind"] == "web" and run["units"][0]["shots"][-1]["scores"] == [state["scores"]["human"], state["scores"]["random"]]


# ----------------------------------------------------------------------------- the server process


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_slow_agent_does_not_block_a_shot(monkeypatch, out_dir):
    """The endpoints that compute run in the thread pool: a shot is answered while an agent thinks."""
    import uvicorn

    import billiards.web.agents as web_agents

    real_ask = web_agents.ask

    def slow_ask(*args, **kwargs):
        time.sleep(1.5)
        return real_ask(*args, **kwargs)

    monkeypatch.setattr(web_agents, "ask", slow_ask)
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
            with urllib.request.urlopen(req, timeout=30) as resp:
                return json.loads(resp.read())

        slow = threading.Thread(target=post, args=("/api/agent", {"positions": RACK, "agent": "random"}))
        t0 = time.perf_counter()
        slow.start()
        time.sleep(0.3)
        assert post("/api/shot", GOOD)["final"]
        assert time.perf_counter() - t0 < 1.2, "the shot waited for the agent"
        slow.join(30)
    finally:
        server.should_exit = True
        thread.join(10)


@pytest.mark.slow
def test_python_m_billiards_web_prints_its_url_and_serves(out_dir):
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "billiards.web", "--port", "0", "--out", str(out_dir)], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stdout.readline().strip()
        assert line.startswith("billiards viewer: http://127.0.0.1:"), line + proc.stderr.read()[-2000:] if not line else line
        url = line.split(": ", 1)[1]
        with urllib.request.urlopen(url + "api/config", timeout=60) as resp:
            assert "korean_medium" in json.loads(resp.read())["physics"]
        with urllib.request.urlopen(url, timeout=60) as resp:
            assert b"/static/app.js" in resp.read()
    finally:
        proc.terminate()
        proc.wait(30)
