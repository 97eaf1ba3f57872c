"""A SHA-256 fingerprint of everything the simulator outputs, over a fixed large set of shots.

    NUMBA_NUM_THREADS=1 python benchmarks/kernel_fingerprint.py [--shots 20000] [--expect HEX]

A refactor of the kernel that claims to keep its behaviour bit for bit must print the same
hash before and after. Every section hashes the raw bytes of the outputs:

* ``batch/<physics>``: ``simulate_batch`` (the parallel and the serial kernel) on ``--shots``
  random racks and actions of the preset: rest positions, hits, first contact, second red,
  closest approaches, cushions, events, duration, truncated, timed out;
* ``shot/<physics>``: ``simulate_shot`` on the same shots (the single-shot path with the
  event log: event times, kinds, balls, others, every ball's state after each event);
* ``opening/<physics>``: shots from the opening rack, with event logs;
* ``fuzz/<physics>/<family>``: the adversarial racks and actions of ``benchmarks/fuzz.py``
  (touching clusters, balls on the rails, extreme aims, powers and tips), and chained
  innings of them, with event logs for a share;
* ``variants``: the elastic ball-ball model, squirt, a short max_time and a small max_events
  (the branches the presets do not take);
* ``trajectory``: sampled trajectories of a few shots (the closed-form evolution).

Prints a hash per section and the total; ``--expect`` exits 1 unless the total matches.
Results do not depend on the thread count (the batch kernel is bit-identical to the serial
one), but the hash may differ across machines with a different libm.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]
from _shots import random_shots, report_fingerprint  # noqa: E402
from fuzz import make_actions, make_racks, uniform_actions  # noqa: E402

from billiards.physics import (  # noqa: E402
    PRESETS, canonical_rack, simulate_batch, simulate_shot, trajectory,
)


class Fingerprint:
    def __init__(self):
        self.total = hashlib.sha256()
        self.sections: dict[str, str] = {}

    def add(self, name: str, *arrays) -> None:
        h = hashlib.sha256()
        for a in arrays:
            a = np.ascontiguousarray(a)
            h.update(str(a.dtype).encode() + str(a.shape).encode())
            h.update(a.tobytes())
        self.sections[name] = h.hexdigest()
        self.total.update(name.encode() + h.digest())


def batch_arrays(res):
    return (res.positions, res.score, res.foul, res.miss, res.first_contact, res.hits, res.closest,
            res.cushions, res.n_events, res.duration, res.truncated, res.second_red, res.timed_out)


def shot_arrays(racks, actions, params):
    out = []
    for r, a in zip(racks, actions):
        res = simulate_shot(r, a, params)
        out += [res.positions, np.array([res.score, res.foul, res.miss, res.truncated, res.timed_out]),
                np.array([res.first_contact, res.second_red, res.cushions, res.n_events]), res.hits,
                res.closest, np.array([res.duration]), res.event_time, res.event_kind, res.event_ball,
                res.event_other, res.event_state]
    return out


def fingerprint(shots: int, seed: int) -> Fingerprint:
    fp = Fingerprint()
    for name, params in PRESETS.items():
        racks, actions = random_shots(shots, seed, params)
        fp.add(f"batch/{name}", *batch_arrays(simulate_batch(racks, actions, params)))
        small = min(shots, 63)  # below PARALLEL_MIN_BATCH: the serial kernel
        fp.add(f"batch_serial/{name}", *batch_arrays(simulate_batch(racks[:small], actions[:small], params)))
        fp.add(f"shot/{name}", *shot_arrays(racks, actions, params))

        rng = np.random.default_rng(seed + 1)
        n_open = max(shots // 20, 1)
        opening = np.repeat(canonical_rack(params)[None], n_open, axis=0)
        acts = uniform_actions(rng, n_open)
        fp.add(f"opening/{name}", *batch_arrays(simulate_batch(opening, acts, params)),
               *shot_arrays(opening, acts, params))

        for family in ("contacts", "rails", "natural"):
            racks = make_racks(rng, family, shots // 2, params)
            acts = make_actions(rng, racks, params)
            logged = max(shots // 20, 1)
            fp.add(f"fuzz/{name}/{family}", *batch_arrays(simulate_batch(racks, acts, params)),
                   *shot_arrays(racks[:logged], acts[:logged], params))
        lanes = max(shots // 200, 1)
        racks = make_racks(rng, "chained", lanes, params)
        chain = []
        for k in range(20):
            acts = make_actions(rng, racks, params) if k % 2 else uniform_actions(rng, lanes)
            res = simulate_batch(racks, acts, params)
            chain += batch_arrays(res)
            chain += shot_arrays(racks[:5], acts[:5], params)
            racks = res.positions
        fp.add(f"fuzz/{name}/chained", *chain)

    base = PRESETS["korean_medium"]
    variants = {
        "elastic": dataclasses.replace(base, ball_ball="elastic"),
        "squirt": dataclasses.replace(base, squirt=True),
        "max_time_1s": dataclasses.replace(base, max_time=1.0),
        "max_events_8": dataclasses.replace(base, max_events=8),
        "intl_elastic_squirt": dataclasses.replace(PRESETS["international"], ball_ball="elastic", squirt=True),
    }
    n_var = max(shots // 10, 1)
    for name, params in variants.items():
        racks, actions = random_shots(n_var, seed + 2, params)
        fp.add(f"variants/{name}", *batch_arrays(simulate_batch(racks, actions, params)),
               *shot_arrays(racks[:n_var // 5], actions[:n_var // 5], params))

    traj = []
    for name, params in PRESETS.items():
        racks, actions = random_shots(20, seed + 3, params)
        for r, a in zip(racks, actions):
            traj += list(trajectory(simulate_shot(r, a, params), 1.0 / 30.0, params))
    fp.add("trajectory", *traj)
    return fp


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--shots", type=int, default=20000, help="random shots per preset (the other sets scale with it)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--expect", default=None, help="the total hash this run must reproduce")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    fp = fingerprint(args.shots, args.seed)
    report_fingerprint(fp.sections, fp.total.hexdigest(), time.perf_counter() - t0, f"--shots {args.shots} --seed {args.seed}",
                       args.expect, width=32)


if __name__ == "__main__":
    main()
