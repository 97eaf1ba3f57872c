"""The viewer's page in a real browser: headless Chromium (Debian's ``chromium``) driven by
Playwright, against the app served by uvicorn in a thread. It replays a committed P3 chain to
its end (the end positions the page reports are the simulator's), opens a benchmark scorecard's
chain, played again by its search agent, and steps through it shot by shot with what the
search considered, plays a shot in the lab and a match against ``random`` to its end, with no
console error. Then what a person playing expects: shoot and start locked while a request is
answered (repeated clicks play one shot, start one match), each turn starting from the
person's own aim with the aim guide and the cue drawn, keyboard aiming, the spin indicator,
the lab's undo and an agent's shot beside the person's, the running score of a league replay
and a link to a replayed shot, the 409 sentence, the "preparing the simulator" banner; and, on a
phone-sized screen by touch (390 x 844), the layout (the page as wide as the screen, the panel
below the table), a ball dragged by touch, and a whole match against ``greedy`` played by taps
to its end through a reload and a server restart (a new app over the same folder, same port).
Skipped, saying why, where Playwright or a Chromium binary is missing (``.ci/run`` installs
both). Chromium is started as :mod:`billiards.web.browser` says (``/usr/bin/chromium`` or the
first ``chromium`` on PATH, headless, no sandbox, no GPU, no background networking). With
``VIEWER_SCREENSHOTS=docs/img`` the tests write the docs' screenshots of a match, the phone
layout and the lab there."""

from __future__ import annotations

import json
import math
import os
import socket
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.slow

sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (pip install -e '.[test]')")
pytest.importorskip("uvicorn")

from billiards.files import verify  # noqa: E402
from billiards.physics import get_params, simulate_shot  # noqa: E402
from billiards.web import create_app  # noqa: E402
from billiards.web.browser import chromium_binary, launch, serving  # noqa: E402

P3_RUN = "results/search/paper/table6/geometric/h2_p3"


class Served(str):
    """The URL of a served app, with the app."""

    app = None


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    app = create_app(out_dir=tmp_path_factory.mktemp("web_out"))
    with serving(app) as url:
        served = Served(url)
        served.app = app
        yield served


@pytest.fixture(scope="module")
def browser():
    if chromium_binary() is None:
        pytest.skip("no Chromium binary (/usr/bin/chromium or chromium on PATH): apt-get install chromium")
    with sync_api.sync_playwright() as p:
        b = launch(p)
        yield b
        b.close()


def open_page(browser, url: str, **context):
    """A new page (its own context: ``context`` as Playwright's new_context takes it) at ``url``, ready."""
    pg = browser.new_context(**{"viewport": {"width": 1280, "height": 900}, **context}).new_page()
    pg.set_default_timeout(600_000)  # Playwright's limits (30 s by default) guard against a hang only
    pg.console_errors = []
    pg.on("console", lambda m: pg.console_errors.append(m.text) if m.type == "error" and "409" not in m.text else None)
    pg.on("pageerror", lambda e: pg.console_errors.append(f"page error: {e}"))
    pg.goto(url)
    pg.wait_for_function("window.billiards && window.billiards.ready", timeout=600_000)  # a limit against a hang only
    return pg


@pytest.fixture(scope="module")
def page(browser, server):
    pg = open_page(browser, server)
    yield pg
    pg.context.close()


def wait_until(pg, condition: str, timeout_s: float = 600.0, skip_animation: bool = True):
    """Poll ``condition`` (JavaScript) until true; meanwhile press the to-the-end button so that
    the shots after the first end at once (the animation itself runs in the first one)."""
    deadline = time.monotonic() + timeout_s
    while not pg.evaluate(condition):
        assert time.monotonic() < deadline, f"timed out waiting for {condition}; status: {pg.inner_text('#status')}"
        if skip_animation and pg.evaluate("window.billiards.anim.state === 'running'"):
            pg.click("#btn-end")
        time.sleep(0.1)


def test_replay_of_a_committed_p3_chain_ends_where_the_simulator_does(page):
    page.select_option("#run-select", P3_RUN)
    page.wait_for_function("window.billiards.replay.count > 0", timeout=600_000)
    run = page.evaluate(f"fetch('/api/run?path={P3_RUN}').then(r => r.json())")
    chain = run["units"][0]
    page.select_option("#speed", "4")
    page.click("#btn-play")
    wait_until(page, "window.billiards.replay.finals[0] !== undefined", skip_animation=False)  # the first shot animates
    assert page.evaluate("window.billiards.replay.frames[0]") > 10  # drawn frame by frame
    wait_until(page, "window.billiards.replay.done")
    finals = page.evaluate("window.billiards.replay.finals")
    assert len(finals) == len(chain["shots"])
    for k, shot in enumerate(chain["shots"]):
        res = simulate_shot(np.array(shot["positions"]), np.array(shot["played"]), get_params(run["physics"]))
        assert finals[str(k)] == res.positions.tolist(), f"shot {k}"
    assert page.get_attribute("#table", "data-final") is not None
    assert page.console_errors == []


def test_a_scorecard_chain_played_again_steps_shot_by_shot(page):
    """Chain 18 of h2's exact P3 scorecard (2 points, 3 shots): played again by its agent, the
    page says it gives the ledger's record; each step's end is the simulator's, and each shot
    shows what the search considered (its candidates drawn, listed)."""
    run = "results/bench/scorecards/p3-exact-v1/h2_geometric"
    page.click("#tabs button[data-view=replay]")
    page.select_option("#speed", "4")
    page.select_option("#run-select", run)
    wait_until(page, f"window.billiards.replay.path === '{run}' && window.billiards.replay.count > 0 && window.billiards.busy === 0")
    page.select_option("#unit-select", "18")
    wait_until(page, "window.billiards.replay.unit === '18' && window.billiards.replay.count === 3 && window.billiards.busy === 0")
    check = page.evaluate("window.billiards.replay.check")
    assert check["reproduced"] is True and "gives the ledger's record" in check["check"]
    assert "gives the ledger's record" in page.inner_text("#run-note")
    unit = page.evaluate(f"fetch('/api/run?path={run}&unit=18').then(r => r.json())")["units"][0]
    for k in range(3):
        if k:
            page.click("#btn-next")
        wait_until(page, f"window.billiards.replay.index === {k} && window.billiards.replay.finals[{k}] !== undefined")
        wait_until(page, f"window.billiards.replay.considered[{k}] !== undefined && window.billiards.busy === 0")
        assert page.inner_text("#shot-label") == f"shot {k + 1} / 3"
        considered = page.evaluate(f"window.billiards.replay.considered[{k}]")
        assert considered["recorded"] == unit["shots"][k]["commanded"] and considered["considered"]["candidates"]["top"]
        assert "candidates" in page.inner_text("#considered-info")
        assert page.locator("#candidates tbody tr").count() == len(considered["considered"]["candidates"]["top"])
    finals = page.evaluate("window.billiards.replay.finals")
    for k, shot in enumerate(unit["shots"]):
        assert finals[str(k)] == simulate_shot(np.array(shot["positions"]), np.array(shot["played"])).positions.tolist(), f"shot {k}"
        if k + 1 < len(unit["shots"]):
            assert finals[str(k)] == unit["shots"][k + 1]["positions"]
    assert [s["scored"] for s in unit["shots"]] == [True, True, False]
    assert page.console_errors == []


def test_a_lab_shot_is_the_simulator_s(page):
    page.click("#tabs button[data-view=lab]")
    page.fill("#in-theta", "97.5")
    page.fill("#in-a", "0.3")
    page.click("#btn-shoot")
    wait_until(page, "window.billiards.lab.shots > 0")
    lab = page.evaluate("window.billiards.lab")
    assert lab["action"][2] == 0.3 and abs(lab["action"][0] - np.radians(97.5)) < 1e-12
    assert lab["final"] == simulate_shot(np.array(lab["positions"]), np.array(lab["action"])).positions.tolist()
    assert page.console_errors == []


def test_a_match_against_random_plays_to_its_end(page):
    fill_match_form(page, opponent="random", noise="none", target=1, hint="search:h2")
    page.click("#btn-start")
    wait_until(page, "window.billiards.match.state && window.billiards.match.state.id")
    for _ in range(15):
        wait_until(page, "!window.billiards.match.pending && window.billiards.busy === 0")
        if page.evaluate("window.billiards.match.over"):
            break
        assert page.evaluate("window.billiards.match.state.to_play") == "human"
        page.evaluate("window.billiards.lab.agent = null")
        page.click("#btn-hint")  # the human's shot: search:h2's, from the table as the page shows it
        wait_until(page, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
        page.click("#btn-hint-take")
        page.click("#btn-shoot")
        wait_until(page, "!window.billiards.match.pending && window.billiards.busy === 0")
    state = page.evaluate("window.billiards.match.state")
    assert state["over"] and max(state["scores"].values()) == 1
    assert "win" in page.inner_text("#match-info") and "Saved" in page.inner_text("#match-info")
    finals = page.evaluate("window.billiards.match.finals")
    assert finals and finals[-1] == state["positions"]
    assert page.console_errors == []


# ----------------------------------------------------------------------------- playing as a person plays

SCREENSHOTS = os.environ.get("VIEWER_SCREENSHOTS")


def screenshot(pg, name: str) -> None:
    """docs/img's screenshot ``name`` (with VIEWER_SCREENSHOTS=<folder>), CSS pixels."""
    if SCREENSHOTS:
        Path(SCREENSHOTS).mkdir(parents=True, exist_ok=True)
        pg.screenshot(path=str(Path(SCREENSHOTS) / name), scale="css")


MATCH_FORM = {"opponent": "#play-opponent", "noise": "#play-noise", "target": "#play-target", "seed": "#play-seed",
              "first": "#play-first", "hint": "#hint-select", "speed": "#speed"}  # the play view's fields
TYPED = ("target", "seed")  # number inputs; the others are selects


def fill_match_form(pg, tap: bool = False, **fields) -> None:
    """The play view opened (by a tap on a phone) and each of ``fields`` set in its form (keys of
    :data:`MATCH_FORM`); the match is not started."""
    (pg.tap if tap else pg.click)("#tabs button[data-view=play]")
    for key, value in fields.items():
        (pg.fill if key in TYPED else pg.select_option)(MATCH_FORM[key], str(value))


def idle(pg, timeout_s: float = 600.0) -> None:
    """Until no match request is in flight and no shot animates (each shot skipped to its end)."""
    wait_until(pg, "!window.billiards.match.pending && window.billiards.busy === 0 && window.billiards.anim.state !== 'running'",
               timeout_s)


def ledger(out_dir: Path, match_id: str) -> list[dict]:
    path = out_dir / "matches" / match_id / "shots.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def nearest_red_theta(positions) -> float:
    cue = np.array(positions[0])
    red = min((np.array(positions[k]) for k in (2, 3)), key=lambda r: np.hypot(*(r - cue)))
    return math.atan2(red[1] - cue[1], red[0] - cue[0]) % (2 * math.pi)


def server_state(pg, match_id: str) -> dict:
    return pg.evaluate(f"fetch('/api/match/{match_id}').then(r => r.json())")["state"]


@pytest.fixture(scope="module")
def out_dir(server):
    return Path(server.app.state.matches.out_dir)


def test_start_and_shoot_are_locked_while_answered_and_each_turn_starts_from_the_person_s_aim(page, out_dir, monkeypatch):
    """Three clicks on start make one match; four clicks on shoot ~120 ms apart (and four sent in
    one go) play one shot; after the opponent's turns the controls hold the person's own power and
    tip, aimed at the nearest red, the guide and the cue drawn (not the opponent's last shot)."""
    from billiards.web.match import Match

    start, shot = Match.start, Match.human_shot  # each answer takes a second at least: the clicks below come while it is awaited
    monkeypatch.setattr(Match, "start", lambda self: (time.sleep(1.0), start(self))[1])
    monkeypatch.setattr(Match, "human_shot", lambda self, *a: (time.sleep(1.0), shot(self, *a))[1])
    # greedy breaks: the person's first turn follows its shots
    fill_match_form(page, opponent="greedy", noise="fastfiz_x5", target=10, seed=3, first="agent", speed=4)
    before = set(p.name for p in (out_dir / "matches").iterdir()) if (out_dir / "matches").is_dir() else set()
    starts = page.evaluate("window.billiards.match.starts")
    page.evaluate("for (let i = 0; i < 3; i++) document.getElementById('btn-start').click()")  # three clicks in one go
    for _ in range(2):  # and two more while it is answered: the button is disabled
        time.sleep(0.12)
        page.click("#btn-start", force=True)
    idle(page)
    state = page.evaluate("window.billiards.match.state")
    assert page.evaluate("window.billiards.match.starts") == starts + 1
    assert set(p.name for p in (out_dir / "matches").iterdir()) - before == {state["id"]}
    assert page.evaluate("location.hash") == f"#match={state['id']}"
    assert state["to_play"] == "human" and state["turn"] >= 1  # greedy's break came first
    opp_last = ledger(out_dir, state["id"])[-1]["commanded"]
    aim = page.evaluate("window.billiards.aim")
    assert aim == {"theta": pytest.approx(nearest_red_theta(state["positions"]), abs=1e-12), "p": 0.5, "a": 0, "b": 0}
    assert [aim["theta"], aim["p"], aim["a"], aim["b"]] != opp_last
    guide = page.evaluate("window.billiards.guide")
    assert guide is not None and guide["kind"] in ("ball", "cushion")  # drawn without a click on the table
    assert page.is_enabled("#btn-shoot")

    page.fill("#in-power", "0.73")  # the person's own power and tip
    page.dispatch_event("#in-power", "input")
    page.fill("#in-a", "0.2")
    requests = page.evaluate("window.billiards.match.shotRequests")
    turn = state["turn"]
    page.evaluate("for (let i = 0; i < 4; i++) document.getElementById('btn-shoot').click()")
    for _ in range(3):
        time.sleep(0.12)
        page.click("#btn-shoot", force=True)
    idle(page)
    assert page.evaluate("window.billiards.match.shotRequests") == requests + 1
    records = ledger(out_dir, state["id"])
    assert [r["who"] for r in records[turn:]].count("human") == 1 and records[turn]["turn"] == turn
    state = page.evaluate("window.billiards.match.state")
    assert state["turn"] == len(records)
    if not state["over"]:
        aim = page.evaluate("window.billiards.aim")
        assert (aim["p"], aim["a"], aim["b"]) == (0.73, 0.2, 0) and aim["theta"] == pytest.approx(nearest_red_theta(state["positions"]))
    # the same turn sent again (another tab, a stale page): one sentence, the page back on the server's table
    stale = page.evaluate(f"""fetch('/api/match/{state["id"]}/shot', {{method: 'POST', headers: {{'content-type': 'application/json'}},
        body: JSON.stringify({{action: [1, 0.5, 0, 0], turn: {turn}}})}}).then(async r => [r.status, await r.json()])""")
    assert stale[0] == 409 and stale[1] == {"error": stale[1]["error"]} and "was played already" in stale[1]["error"]
    assert page.console_errors == []


def test_a_turn_played_elsewhere_is_a_sentence_and_the_page_takes_the_server_s_table(page):
    fill_match_form(page, opponent="random", noise="none", first="human", target=10)
    page.click("#btn-start")
    idle(page)
    state = page.evaluate("window.billiards.match.state")
    played = page.evaluate(f"""fetch('/api/match/{state["id"]}/shot', {{method: 'POST', headers: {{'content-type': 'application/json'}},
        body: JSON.stringify({{action: [1, 0.5, 0, 0], turn: {state["turn"]}}})}}).then(r => r.json())""")["state"]
    page.click("#btn-shoot")  # the page still shows turn 0
    idle(page)
    status = page.inner_text("#status")
    assert f"turn {state['turn']} of match {state['id']} was played already" in status and "{" not in status
    assert page.evaluate("window.billiards.match.state") == played
    assert page.evaluate("window.billiards.aim.theta") == pytest.approx(nearest_red_theta(played["positions"]))
    page.console_errors.clear()  # the 409 of this test, logged by the browser as a failed load


def test_the_table_takes_keyboard_focus_and_the_arrows_aim(page):
    page.click("#tabs button[data-view=lab]")
    page.click("#btn-rack")
    assert page.get_attribute("#table", "tabindex") == "0"
    page.focus("#table")
    assert page.evaluate("document.activeElement.id") == "table"
    theta, p = page.evaluate("[window.billiards.aim.theta, window.billiards.aim.p]")
    page.keyboard.press("ArrowLeft")
    page.keyboard.press("Shift+ArrowLeft")
    page.keyboard.press("ArrowUp")
    aim = page.evaluate("window.billiards.aim")
    assert aim["theta"] == pytest.approx((theta + math.radians(5.5)) % (2 * math.pi)) and aim["p"] == pytest.approx(p + 0.02)
    shots = page.evaluate("window.billiards.lab.shots")
    page.keyboard.press("Enter")
    wait_until(page, f"window.billiards.lab.shots === {shots + 1}")
    assert page.evaluate("window.billiards.lab.action") == [aim["theta"], aim["p"], aim["a"], aim["b"]]


def test_the_spin_indicator_follows_the_pointer_and_a_drag_sets_the_tip(page):
    page.click("#tabs button[data-view=lab]")
    box = page.locator("#tip").bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(cx - 20, cy - 20)
    hover = page.evaluate("window.billiards.tipHover")
    assert hover[0] > 0.3 and hover[1] > 0.3  # up-left of centre: left english, top spin
    assert page.evaluate("[window.billiards.aim.a, window.billiards.aim.b]") != hover  # only shown, not set
    page.mouse.down()
    page.mouse.move(cx + 15, cy + 10, steps=4)
    page.mouse.up()
    a, b = page.evaluate("[window.billiards.aim.a, window.billiards.aim.b]")
    assert a < -0.2 and b < -0.1 and page.input_value("#in-a") == f"{a:.2f}"


def test_the_lab_s_undo_and_an_agent_s_shot_beside_the_person_s(page):
    page.click("#tabs button[data-view=lab]")
    page.click("#btn-rack")
    rack, undos = page.evaluate("window.billiards.balls"), page.evaluate("window.billiards.lab.undo")
    red = page.evaluate("window.billiards.toScreen(window.billiards.balls[2])")
    page.mouse.move(*red)
    page.mouse.down()
    page.mouse.move(red[0] + 60, red[1] - 40, steps=5)
    page.mouse.up()
    moved = page.evaluate("window.billiards.balls")
    assert moved[2] != rack[2] and moved[:2] == rack[:2]
    mine = page.evaluate("window.billiards.aim")
    page.select_option("#agent-select", "search:h2")
    page.evaluate("window.billiards.lab.agent = null")
    page.click("#btn-ask")
    wait_until(page, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
    agent = page.evaluate("window.billiards.lab.agent")
    assert page.evaluate("window.billiards.aim") == mine  # the person's shot stands
    assert page.is_visible("#btn-agent-play") and "cyan line" in page.inner_text("#agent-info")
    screenshot(page, "viewer_lab.png")
    shots = page.evaluate("window.billiards.lab.shots")
    page.click("#btn-agent-play")
    wait_until(page, f"window.billiards.lab.shots === {shots + 1} && window.billiards.anim.state === 'idle'")
    assert page.evaluate("window.billiards.lab.action") == agent["action"] and page.evaluate("window.billiards.aim") == mine
    page.click("#btn-undo")  # before the agent's shot
    assert page.evaluate("window.billiards.balls") == moved
    page.focus("#table")
    page.keyboard.press("Control+z")  # before the ball was moved
    assert page.evaluate("window.billiards.balls") == rack and page.evaluate("window.billiards.lab.undo") == undos
    page.click("#btn-ask")
    wait_until(page, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
    page.click("#btn-agent-take")
    assert list(page.evaluate("window.billiards.aim").values()) == page.evaluate("window.billiards.lab.agent.action")
    assert page.console_errors == []


def test_a_league_replay_shows_the_running_score_and_a_shot_s_link_opens_it(page, browser, server):
    run = "results/sagu/fastfiz_x5_run"
    page.click("#tabs button[data-view=replay]")
    page.select_option("#speed", "4")
    page.select_option("#run-select", run)
    wait_until(page, f"window.billiards.replay.path === '{run}' && window.billiards.replay.count > 0 && window.billiards.busy === 0",
               skip_animation=False)
    unit = page.evaluate(f"fetch('/api/run?path={run}&unit=0').then(r => r.json())")["units"][0]
    assert page.is_visible("#scorebar") and page.evaluate("window.billiards.replay.scores") == [0, 0]
    assert page.is_disabled("#in-theta") and page.is_disabled("#in-power")  # a replay's shot is the record's
    assert "outcome shows once" in page.inner_text("#outcome")  # at its start, paused: no outcome yet
    for k in range(3):
        if k:
            page.click("#btn-next")
            wait_until(page, f"window.billiards.replay.index === {k} && window.billiards.busy === 0", skip_animation=False)
            assert "outcome shows once" in page.inner_text("#outcome")
            assert page.evaluate("window.billiards.replay.scores") == unit["shots"][k - 1]["scores"]  # before it
        page.click("#btn-end")
        wait_until(page, f"window.billiards.replay.finals[{k}] !== undefined")
        assert page.evaluate("window.billiards.replay.scores") == unit["shots"][k]["scores"]
        assert page.inner_text("#sb-white-score") == f"{unit['shots'][k]['scores'][0]:.0f}"
        assert "outcome shows once" not in page.inner_text("#outcome")
    link = page.get_attribute("#shot-link", "href")
    assert link.endswith(f"#run={run}&unit=0&shot=3") and page.evaluate("location.href") == link
    other = open_page(browser, link)
    wait_until(other, "window.billiards.replay.index === 2 && window.billiards.busy === 0")
    assert other.evaluate("window.billiards.replay.path") == run and other.input_value("#unit-select") == "0"
    assert other.inner_text("#shot-label") == f"shot 3 / {len(unit['shots'])}"
    assert other.console_errors == []
    other.context.close()


def test_the_page_says_it_prepares_the_simulator_on_first_use(browser, monkeypatch, tmp_path):
    import billiards.web.catalogue as web_catalogue

    app = create_app(out_dir=tmp_path)
    sim = app.state.simulator
    sim.cached, sim.ready = False, False  # as on a machine whose numba cache is empty
    real_ask = web_catalogue.ask

    def slow_ask(*args, **kwargs):
        time.sleep(1.5)
        return real_ask(*args, **kwargs)

    monkeypatch.setattr(web_catalogue, "ask", slow_ask)
    with serving(app) as url:
        pg = open_page(browser, url)
        wait_until(pg, "!document.getElementById('sim-banner').classList.contains('hidden')")
        assert "Preparing the simulator" in pg.inner_text("#sim-banner")
        assert f"about {sim.expected_s} s" in pg.inner_text("#sim-banner")
        pg.click("#tabs button[data-view=lab]")
        pg.click("#btn-ask")
        wait_until(pg, "!document.getElementById('table-wait').classList.contains('hidden')", skip_animation=False)
        assert "preparing the simulator" in pg.inner_text("#table-wait") and pg.is_visible("#busy")
        sim.ready = True
        wait_until(pg, "document.getElementById('sim-banner').classList.contains('hidden') && window.billiards.busy === 0")
        wait_until(pg, "document.getElementById('table-wait').classList.contains('hidden')")
        assert pg.console_errors == []
        pg.context.close()


PHONE = {"viewport": {"width": 390, "height": 844}, "has_touch": True, "is_mobile": True, "device_scale_factor": 2}


def touch_drag(pg, points) -> None:
    """A finger on the screen along ``points`` (viewport CSS pixels), through Chromium's touch input."""
    cdp = pg.context.new_cdp_session(pg)
    cdp.send("Input.dispatchTouchEvent", {"type": "touchStart", "touchPoints": [{"x": points[0][0], "y": points[0][1]}]})
    for x, y in points[1:]:
        cdp.send("Input.dispatchTouchEvent", {"type": "touchMove", "touchPoints": [{"x": x, "y": y}]})
    cdp.send("Input.dispatchTouchEvent", {"type": "touchEnd", "touchPoints": []})
    cdp.detach()
    time.sleep(0.4)  # a finger's pause: a tap within Chromium's double-tap time after a touch sequence gets no click


def test_a_phone_lays_the_page_out_across_its_width_and_a_finger_moves_a_ball(browser, server):
    pg = open_page(browser, server + "#view=lab", **PHONE)
    assert "width=device-width" in pg.get_attribute("meta[name=viewport]", "content")
    assert pg.evaluate("[document.documentElement.scrollWidth, document.documentElement.clientWidth]") == [390, 390]
    table, side = pg.locator("#table").bounding_box(), pg.locator("#side").bounding_box()
    assert table["x"] >= 0 and table["x"] + table["width"] <= 390 and side["width"] <= 390
    assert side["y"] >= table["y"] + table["height"]  # the panel below the table
    assert pg.locator("#btn-shoot").bounding_box()["y"] + 40 < 844  # shoot reachable without scrolling
    pg.tap("#btn-rack")
    pg.evaluate("window.scrollTo(0, 0)")
    before = pg.evaluate("window.billiards.balls")
    x, y = pg.evaluate("window.billiards.toScreen(window.billiards.balls[3])")
    assert 0 < x < 390 and 0 < y < 844
    touch_drag(pg, [(x, y), (x - 10, y + 15), (x - 30, y + 40), (x - 40, y + 60)])
    after = pg.evaluate("window.billiards.balls")
    assert after[3] != before[3] and after[3][1] < before[3][1] and after[:3] == before[:3]  # dragged down the table
    assert pg.evaluate("window.billiards.lab.undo") >= 1
    assert pg.console_errors == []
    pg.context.close()


def test_a_phone_plays_a_match_against_greedy_by_touch_through_a_reload_and_a_server_restart(browser, tmp_path):
    """A whole match to 10 by taps on a 390 x 844 touch screen: the first shot aimed by a tap on
    the table and powered by pulling the cue back with a finger, the others the hint's (tapped,
    taken, shot); a reload at the person's second turn and a server restart (a new app over the
    same folder, on the same port, the page left open) at the third. The match ends; its folder
    verifies; rematch starts the next."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "web"
    servers = [serving(create_app(out_dir=out), port=port)]
    url = servers[0].__enter__()
    try:
        pg = open_page(browser, url, **PHONE)
        fill_match_form(pg, tap=True, opponent="greedy", noise="fastfiz_x5", target=10, seed=1, first="human",
                        hint="search:default", speed=4)
        pg.tap("#btn-start")
        idle(pg)
        match_id = pg.evaluate("window.billiards.match.state.id")
        assert pg.evaluate("location.hash") == f"#match={match_id}"
        turns, reloaded, restarted = 0, None, None
        while not pg.evaluate("window.billiards.match.state.over"):
            turns += 1
            assert turns <= 60, "the match does not end"
            if turns == 2:  # a reload in the middle: the same match, table and score
                held = server_state(pg, match_id)
                pg.reload()
                pg.wait_for_function("window.billiards && window.billiards.ready")
                idle(pg)
                assert pg.evaluate("window.billiards.match.state") == held and pg.evaluate("location.hash") == f"#match={match_id}"
                assert pg.evaluate("window.billiards.guide") is not None
                assert pg.inner_text("#sb-white-score") == f"{held['scores']['human']:.0f}"
                reloaded = held["turn"]
                pg.evaluate("window.scrollTo(0, 0)")
                screenshot(pg, "viewer_phone.png")
            if turns == 3:  # a server restart in the middle: the page's next shot is answered by the new server
                servers[0].__exit__(None, None, None)
                servers[0] = serving(create_app(out_dir=out), port=port)
                assert servers[0].__enter__() == url
                restarted = pg.evaluate("window.billiards.match.state.turn")
            state = pg.evaluate("window.billiards.match.state")
            assert state["to_play"] == "human"
            if turns == 1:  # aim by a tap at the nearest red, then pull the cue back from the white with a finger
                red = min((2, 3), key=lambda k: math.dist(state["positions"][k], state["positions"][0]))
                pg.evaluate("document.getElementById('table').scrollIntoView()")
                rx, ry = pg.evaluate(f"window.billiards.toScreen(window.billiards.balls[{red}])")
                pg.touchscreen.tap(rx, ry)
                theta = pg.evaluate("window.billiards.aim.theta")
                assert theta == pytest.approx(nearest_red_theta(state["positions"]), abs=0.05)
                wx, wy = pg.evaluate("window.billiards.toScreen(window.billiards.balls[0])")
                ux, uy = (wx - rx) / math.hypot(wx - rx, wy - ry), (wy - ry) / math.hypot(wx - rx, wy - ry)
                touch_drag(pg, [(wx + 3 * ux, wy + 3 * uy)] + [(wx + d * ux, wy + d * uy) for d in (15, 30, 45, 50)])
                aim = pg.evaluate("window.billiards.aim")
                assert aim["theta"] == pytest.approx(theta, abs=0.05) and 0.2 < aim["p"] < 0.9
            else:
                pg.evaluate("window.billiards.lab.agent = null")
                pg.tap("#btn-hint")
                wait_until(pg, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
                pg.tap("#btn-hint-take")
                assert list(pg.evaluate("window.billiards.aim").values()) == pg.evaluate("window.billiards.lab.agent.action")
            pg.tap("#btn-shoot")
            time.sleep(0.05)
            idle(pg)
            assert pg.evaluate("window.billiards.errors") == [], pg.inner_text("#status")
            assert pg.evaluate("window.billiards.match.state.turn") > state["turn"], "the tap on shoot played no shot"
        state = pg.evaluate("window.billiards.match.state")
        assert reloaded is not None and restarted is not None, f"the match ended after {turns} turns, before the reload and restart"
        assert state["over"] and max(state["scores"].values()) == 10 and state["turn"] > restarted > reloaded
        assert server_state(pg, match_id) == state
        assert ("You win" if state["winner"] == "human" else "greedy wins") in pg.inner_text("#match-info")
        folder = out / "matches" / match_id
        problems, notes = verify(folder)
        assert problems == [] and len(ledger(out, match_id)) == state["turn"]
        assert sorted(p.name for p in folder.iterdir()) == ["league.json", "match.json", "matches.jsonl", "shots.jsonl"]
        assert pg.is_visible("#btn-rematch")
        pg.tap("#btn-rematch")
        idle(pg)
        again = pg.evaluate("window.billiards.match.state")
        assert again["id"] != match_id and (again["seed"], again["first"], again["opponent"]) == (2, "agent", "greedy")
        assert pg.evaluate("location.hash") == f"#match={again['id']}"
        assert pg.console_errors == []
        pg.context.close()
    finally:
        servers[0].__exit__(None, None, None)


def test_a_match_some_exchanges_in_shows_the_score_the_guide_the_cue_and_a_hint_beside(page):
    """A match against greedy a few exchanges in, the person to play: the score, the aim guide, the cue, a hint beside."""
    fill_match_form(page, opponent="greedy", noise="fastfiz_x5", first="human", target=10, seed=7, hint="search:default")
    page.click("#btn-start")
    idle(page)
    for _ in range(3):
        if page.evaluate("window.billiards.match.state.over"):
            break
        page.evaluate("window.billiards.lab.agent = null")
        page.click("#btn-hint")
        wait_until(page, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
        page.click("#btn-hint-take")
        page.click("#btn-shoot")
        idle(page)
    page.evaluate("window.billiards.lab.agent = null")
    page.click("#btn-hint")
    wait_until(page, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
    assert page.evaluate("window.billiards.guide") is not None and page.is_visible("#scorebar")
    screenshot(page, "viewer_play.png")
    assert page.console_errors == []
