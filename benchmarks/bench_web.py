"""The viewer's API from a client's side: round-trip times over HTTP to ``python -m billiards.web``.

    python benchmarks/bench_web.py --out results/bench_web.json

The server runs as its own process (``python -m billiards.web --port 0 --threads 1``), the client
here sends requests one at a time on one kept-alive connection and times each from the first
byte sent to the last byte of the answer read (JSON parsing of the answer included). Measures:

* ``shot``: ``POST /api/shot`` from random racks with random actions, with the paths the page
  draws (1/60 s samples) and without (``paths: false``); the goal: a shot's exact path drawn
  within 50 ms of the request;
* ``agent_h2_ensemble``: ``POST /api/agent`` with ``search:h2/base`` (h2 at 400 simulations over
  the shipped ``base`` ensemble), exact play; goal 30 ms;
* ``agent_default_fastfiz``: ``search:default`` under ``fastfiz`` (the robust search over the
  fastfiz shot ranker, 400 simulations), with the 50 noisy replays of the chosen shot the page
  shows and without them (``replays: 0``); goal 150 ms;
* ``run_p3``: ``GET /api/run`` of a committed P3 run (every chain's last shots);
* ``browser`` (where Playwright and Chromium are installed; ``--no-browser`` to leave it out): in
  headless Chromium (:mod:`billiards.web.browser`), the time from choosing that run in the replay
  view to its first shot animating, and the frames per second while a shot animates at 1x for
  about three seconds (requestAnimationFrame's rate: 60 where the page keeps up with the display).

Each agent's first request (which builds it: configs, networks, first compilations) is reported
apart and left out of the statistics. The agent's own seconds (``seconds`` of its answer) are
reported beside the round trip. The machine's load at the start and end is recorded: on a
shared machine the times include waiting for a core.
"""

from __future__ import annotations

import argparse
import http.client
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from _shots import ROOT, git_commit, write_json  # noqa: E402

from billiards.physics import random_racks  # noqa: E402

P3_RUN = "results/noise/headline/h2_fastfiz_400_p3"


def start_server(out_dir: Path) -> tuple[subprocess.Popen, str, int]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "billiards.web", "--port", "0", "--threads", "1", "--out", str(out_dir)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline().strip()
    if not line.startswith("billiards viewer: http://"):
        proc.kill()
        raise SystemExit(f"the server did not start: {line!r} {proc.stderr.read()[-2000:]}")
    hostport = line.split("://", 1)[1].rstrip("/")
    host, port = hostport.rsplit(":", 1)
    return proc, host, int(port)


class Client:
    def __init__(self, host: str, port: int):
        self.conn = http.client.HTTPConnection(host, port, timeout=300)

    def request(self, method: str, path: str, body: dict | None = None) -> tuple[float, dict, int]:
        data = None if body is None else json.dumps(body).encode()
        headers = {"content-type": "application/json"} if data is not None else {}
        t0 = time.perf_counter()
        self.conn.request(method, path, body=data, headers=headers)
        resp = self.conn.getresponse()
        raw = resp.read()
        out = json.loads(raw)
        ms = 1e3 * (time.perf_counter() - t0)
        if resp.status != 200:
            raise SystemExit(f"{method} {path}: {resp.status} {out}")
        return ms, out, len(raw)


def stats(ms: list[float]) -> dict:
    a = np.asarray(ms)
    return {"n": int(a.size), "median_ms": round(float(np.median(a)), 2), "mean_ms": round(float(a.mean()), 2),
            "p90_ms": round(float(np.percentile(a, 90)), 2), "min_ms": round(float(a.min()), 2), "max_ms": round(float(a.max()), 2)}


def browser_measures(url: str) -> dict:
    """Replay start and animation frame rate in headless Chromium (see the module docstring)."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        return {"skipped": "Playwright is not installed"}
    from billiards.web.browser import chromium_binary, launch

    if chromium_binary() is None:
        return {"skipped": "no Chromium binary"}
    with sync_playwright() as p:
        browser = launch(p)
        pg = browser.new_page(viewport={"width": 1280, "height": 900})
        t0 = time.perf_counter()
        pg.goto(url)
        pg.wait_for_function("window.billiards.ready", timeout=120_000)
        page_ready = time.perf_counter() - t0
        t0 = time.perf_counter()
        pg.select_option("#run-select", P3_RUN)
        pg.wait_for_function("window.billiards.anim.state === 'running'", timeout=120_000)
        replay_start = time.perf_counter() - t0
        pg.click("#btn-play")
        time.sleep(3.0)
        frames, wall, t = pg.evaluate("[window.billiards.anim.frames, window.billiards.anim.wall, window.billiards.anim.t]")
        browser.close()
    return {"page_ready_s": round(page_ready, 3), "run_loaded_and_first_shot_animating_s": round(replay_start, 3),
            "chromium": chromium_binary(), "animation_fps": round(frames / wall, 1) if wall else None, "frames": frames,
            "sim_seconds_shown": round(t, 2),
            "note": "animation_fps: the page's own animation frames per second of wall time while the first shot played at 1x"}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shots", type=int, default=200, help="shot requests (each with and without paths)")
    parser.add_argument("--decisions", type=int, default=40, help="requests per agent (after the one that builds it)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="JSON summary (e.g. results/bench_web.json)")
    parser.add_argument("--no-browser", action="store_true", help="leave out the headless-browser measures")
    args = parser.parse_args(argv)

    import tempfile

    load0 = os.getloadavg()
    rng = np.random.default_rng(args.seed)
    racks = random_racks(rng, max(args.shots, args.decisions + 1))
    summary: dict = {"command": " ".join(["python", "benchmarks/bench_web.py"] + (sys.argv[1:] if argv is None else list(argv))),
                     "commit": git_commit(), "cpus": os.cpu_count(), "load_average_start": [round(x, 2) for x in load0]}
    with tempfile.TemporaryDirectory() as out_dir:
        proc, host, port = start_server(Path(out_dir))
        try:
            c = Client(host, port)
            c.request("GET", "/api/config")
            for _ in range(5):  # warm: the first shots compile nothing (numba's cache) but touch every path once
                c.request("POST", "/api/shot", {"positions": racks[0].tolist(), "action": [1.0, 0.5, 0.0, 0.0]})
            with_paths, without, sizes, frames = [], [], [], []
            for i in range(args.shots):
                action = [float(rng.uniform(0, 2 * np.pi)), float(rng.uniform(0.1, 1.0)), float(rng.uniform(-0.7, 0.7)),
                          float(rng.uniform(-0.7, 0.7))]
                body = {"positions": racks[i].tolist(), "action": action}
                ms, out, size = c.request("POST", "/api/shot", body)
                with_paths.append(ms)
                sizes.append(size)
                frames.append(len(out["paths"]["t"]))
                ms, _, _ = c.request("POST", "/api/shot", {**body, "paths": False})
                without.append(ms)
            summary["shot"] = {"with_paths": stats(with_paths), "without_paths": stats(without),
                               "answer_kb_median": round(float(np.median(sizes)) / 1024, 1), "path_samples_median": int(np.median(frames)),
                               "goal_ms": 50}
            print(f"/api/shot with paths: median {summary['shot']['with_paths']['median_ms']} ms, p90 "
                  f"{summary['shot']['with_paths']['p90_ms']} ms ({summary['shot']['answer_kb_median']} kB); without: "
                  f"median {summary['shot']['without_paths']['median_ms']} ms", flush=True)

            for key, spec, noise, replays, goal in (("agent_h2_ensemble", "search:h2/base", "none", 0, 30),
                                                    ("agent_default_fastfiz", "search:default", "fastfiz", 50, 150),
                                                    ("agent_default_fastfiz_no_replays", "search:default", "fastfiz", 0, 150)):
                first, _, _ = c.request("POST", "/api/agent", {"positions": racks[0].tolist(), "agent": spec, "noise": noise,
                                                              "replays": replays})
                trips, own, sims = [], [], []
                for i in range(1, args.decisions + 1):
                    ms, out, _ = c.request("POST", "/api/agent", {"positions": racks[i].tolist(), "agent": spec, "noise": noise,
                                                                 "seed": i, "replays": replays})
                    trips.append(ms)
                    own.append(1e3 * out["seconds"])
                    sims.append(out["sims"])
                summary[key] = {"agent": spec, "noise": noise, "replays": replays, "first_request_ms": round(first, 1),
                                "sims_per_decision": float(np.mean(sims)), "round_trip": stats(trips), "agent_own": stats(own),
                                "goal_ms": goal}
                print(f"/api/agent {spec} ({noise}, {replays} replays): round trip median {summary[key]['round_trip']['median_ms']} ms "
                      f"(p90 {summary[key]['round_trip']['p90_ms']}), the agent's own {summary[key]['agent_own']['median_ms']} ms; "
                      f"first request {first:.0f} ms", flush=True)

            runs = []
            for _ in range(5):
                ms, out, size = c.request("GET", f"/api/run?path={P3_RUN}")
                runs.append(ms)
            summary["run_p3"] = {"path": P3_RUN, "chains": len(out["units"]), "answer_kb": round(size / 1024, 1), **stats(runs)}
            print(f"/api/run {P3_RUN}: median {summary['run_p3']['median_ms']} ms", flush=True)
            if not args.no_browser:
                summary["browser"] = browser_measures(f"http://{host}:{port}/")
                print("browser:", summary["browser"], flush=True)
        finally:
            proc.terminate()
            proc.wait(30)
    summary["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    write_json(args.out, summary)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
