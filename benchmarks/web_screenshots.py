"""Screenshots of the viewer's three views for docs/viewer.md, taken in headless Chromium.

    python benchmarks/web_screenshots.py [--out docs/img]

Serves the app in this process (matches played here are saved to a temporary folder, not
outputs/web) and drives the page with Playwright, Chromium started as the browser tests start it
(:mod:`billiards.web.browser`):

* ``viewer_replay.png``: a chain of the committed noisy P3 run results/noise/headline/h2_fastfiz_400_p3,
  its third-last shot part-way (commanded aim dashed white, played aim orange);
* ``viewer_considered.png``: a chain of the position-aware search under fastfiz
  (results/noisy_track/headline/position_fastfiz_p3), a shot with what the search considered:
  its candidates (aim lines, listed), the recorded shot's 50 noisy replays (cue-ball ends) and
  the value of their leaves;
* ``viewer_lab.png``: the opening rack, ``search:default`` asked under fastfiz_x5 noise: its shot
  played (one noisy draw) over the cloud of its 50 noisy replays' cue-ball ends (green: scored);
* ``viewer_play.png``: a match against the league's ``greedy`` under fastfiz_x5, after the first
  exchanges (the person's shots taken from ``search:default``'s hints).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from billiards.files import ROOT  # noqa: E402
from billiards.web import create_app  # noqa: E402
from billiards.web.browser import launch, serving  # noqa: E402

RUN = "results/noise/headline/h2_fastfiz_400_p3"
CONSIDERED_RUN = "results/noisy_track/headline/position_fastfiz_p3"


def wait(pg, condition: str, timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not pg.evaluate(condition):
        if time.monotonic() > deadline:
            raise TimeoutError(f"{condition}; status: {pg.inner_text('#status')}")
        time.sleep(0.1)


def scrub(pg, fraction: float) -> None:
    pg.evaluate("(v) => { const s = document.getElementById('scrub'); s.value = v; s.dispatchEvent(new Event('input')); }",
                int(1000 * fraction))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp, serving(create_app(out_dir=Path(tmp))) as url, sync_playwright() as p:
        browser = launch(p)
        pg = browser.new_page(viewport={"width": 1200, "height": 900})
        errors: list[str] = []
        pg.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        pg.goto(url)
        wait(pg, "window.billiards.ready")

        # replay: a noisy chain, a shot part-way
        pg.select_option("#run-select", RUN)
        wait(pg, "window.billiards.replay.count > 0")
        units = pg.evaluate("Array.from(document.querySelectorAll('#unit-select option')).map(o => o.value)")
        pg.select_option("#unit-select", units[3])
        wait(pg, "window.billiards.replay.count > 0 && window.billiards.anim.state === 'running' && window.billiards.busy === 0")
        for k in (1, 2, 3):  # step to the chain's fourth recorded shot
            pg.click("#btn-next")
            wait(pg, f"window.billiards.replay.index === {k} && window.billiards.busy === 0")
            time.sleep(0.3)
        scrub(pg, 0.45)
        time.sleep(0.3)
        pg.screenshot(path=str(args.out / "viewer_replay.png"))

        # replay with what the search considered: the position-aware search's chain, a shot before its end
        pg.select_option("#run-select", CONSIDERED_RUN)
        wait(pg, f"window.billiards.replay.path === '{CONSIDERED_RUN}' && window.billiards.replay.count > 0 && window.billiards.busy === 0")
        units = pg.evaluate("Array.from(document.querySelectorAll('#unit-select option')).map(o => o.value)")
        pg.select_option("#unit-select", units[1])
        wait(pg, "window.billiards.replay.count > 0 && window.billiards.busy === 0")
        for k in (1, 2, 3):
            pg.click("#btn-next")
            wait(pg, f"window.billiards.replay.index === {k} && window.billiards.busy === 0")
        wait(pg, "window.billiards.replay.considered[3] !== undefined && window.billiards.busy === 0")
        pg.click("#btn-end")
        wait(pg, "window.billiards.anim.state === 'done'")
        scrub(pg, 0.0)
        time.sleep(0.3)
        pg.screenshot(path=str(args.out / "viewer_considered.png"))

        # lab: an agent's shot under noise, with its noisy replays
        pg.click("#tabs button[data-view=lab]")
        pg.select_option("#lab-noise", "fastfiz_x5")
        pg.select_option("#agent-select", "search:default")
        pg.evaluate("window.billiards.lab.shots = 0")
        pg.click("#btn-ask")  # the agent's shot stands beside the player's; playing it is a second click
        wait(pg, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
        pg.click("#btn-agent-play")
        wait(pg, "window.billiards.lab.shots > 0")
        time.sleep(0.3)
        pg.screenshot(path=str(args.out / "viewer_lab.png"))

        # play: a match against greedy under fastfiz_x5
        pg.click("#tabs button[data-view=play]")
        pg.select_option("#play-opponent", "greedy")
        pg.select_option("#play-noise", "fastfiz_x5")
        pg.fill("#play-target", "5")
        pg.select_option("#hint-select", "search:default")
        pg.select_option("#speed", "4")
        pg.click("#btn-start")
        wait(pg, "window.billiards.match.state && !window.billiards.match.pending && window.billiards.busy === 0")
        for _ in range(3):
            if pg.evaluate("window.billiards.match.over"):
                break
            pg.evaluate("window.billiards.lab.agent = null")
            pg.click("#btn-hint")
            wait(pg, "window.billiards.lab.agent !== null && window.billiards.busy === 0")
            pg.click("#btn-hint-take")  # the hint drawn beside the player's aim, taken
            pg.click("#btn-shoot")
            time.sleep(0.2)
            while pg.evaluate("window.billiards.match.pending"):
                if pg.evaluate("window.billiards.anim.state === 'running'"):
                    pg.click("#btn-end")
                time.sleep(0.1)
        pg.screenshot(path=str(args.out / "viewer_play.png"))
        browser.close()
    if errors:
        print("console errors:", errors, file=sys.stderr)
        return 1
    for name in ("replay", "considered", "lab", "play"):
        print("wrote", args.out / f"viewer_{name}.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
