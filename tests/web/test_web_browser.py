"""The viewer's page in a real browser: headless Chromium (Debian's ``chromium``) driven by
Playwright, against the app served by uvicorn in a thread. It replays a committed P3 chain to
its end (the end positions the page reports are the simulator's), opens a benchmark scorecard's
chain, played again by its search agent, and steps through it shot by shot with what the
search considered, plays a shot in the lab and a match against ``random`` to its end, with no
console error. Skipped, saying why, where
Playwright or a Chromium binary is missing (``.ci/run`` installs both). Chromium is started as
:mod:`billiards.web.browser` says (``/usr/bin/chromium`` or the first ``chromium`` on PATH,
headless, no sandbox, no GPU, no background networking)."""

from __future__ import annotations

import time

import numpy as np
import pytest

pytestmark = pytest.mark.slow

sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright is not installed (pip install -e '.[test]')")
pytest.importorskip("uvicorn")

from billiards.physics import get_params, simulate_shot  # noqa: E402
from billiards.web import create_app  # noqa: E402
from billiards.web.browser import chromium_binary, launch, serving  # noqa: E402

P3_RUN = "results/search/paper/table6/geometric/h2_p3"


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with serving(create_app(out_dir=tmp_path_factory.mktemp("web_out"))) as url:
        yield url


@pytest.fixture(scope="module")
def page(server):
    if chromium_binary() is None:
        pytest.skip("no Chromium binary (/usr/bin/chromium or chromium on PATH): apt-get install chromium")
    with sync_api.sync_playwright() as p:
        browser = launch(p)
        pg = browser.new_page(viewport={"width": 1280, "height": 900})
        pg.set_default_timeout(600_000)  # Playwright's limits (30 s by default) guard against a hang only
        pg.console_errors = []
        pg.on("console", lambda m: pg.console_errors.append(m.text) if m.type == "error" else None)
        pg.on("pageerror", lambda e: pg.console_errors.append(f"page error: {e}"))
        pg.goto(server)
        pg.wait_for_function("window.billiards && window.billiards.ready", timeout=600_000)  # a limit against a hang only
        yield pg
        browser.close()


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
    page.click("#tabs button[data-view=play]")
    page.select_option("#play-opponent", "random")
    page.select_option("#play-noise", "none")
    page.fill("#play-target", "1")
    page.select_option("#hint-select", "search:h2")
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
        page.click("#btn-shoot")
        wait_until(page, "!window.billiards.match.pending && window.billiards.busy === 0")
    state = page.evaluate("window.billiards.match.state")
    assert state["over"] and max(state["scores"].values()) == 1
    assert "win" in page.inner_text("#match-info") and "Saved" in page.inner_text("#match-info")
    finals = page.evaluate("window.billiards.match.finals")
    assert finals and finals[-1] == state["positions"]
    assert page.console_errors == []
