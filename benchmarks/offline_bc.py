"""Are an expert's shots too many-valued for a Gaussian policy? Behaviour cloning on an offline
dataset with a mixture of K squashed Gaussians, K = 1 being the plain Gaussian.

    python benchmarks/offline_bc.py datasets/none-expert --components 1 8 --epochs 10 --out results/datasets/bc/none-expert.json

Reads a built dataset (``python -m billiards.offline build``) in the agents' own space
(``billiards.offline.space_observation`` / ``space_action``: the carom-feature observation and
the aim-constrained action), holds out its last ``--held-out`` shots, and for each ``--components`` K fits a policy
whose head is a mixture of K Gaussians over atanh of the normalised action (three hidden layers
of ``--hidden``, the mixture's negative log-likelihood, Adam with a one-cycle learning rate, one
CPU thread, seed 0). After every epoch it plays the mode shot (the mean of the heaviest
component, squashed) on the held-out tables under the dataset's noise and reports the share
that score; at the end it scores the policy on the benchmark track of the dataset's noise
(``innings-v1`` exact, ``p1-fastfiz-v1`` under fastfiz), as the offline IQL baseline is scored.

A search's chosen shot is the best of its sampled candidates, so similar tables can have their
labels in unrelated places; a single Gaussian fitted to them averages those places. If a
mixture scores more from the same labels, the labels are many-valued and the policy's form is
part of what limits it.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from _shots import git_commit, write_json  # noqa: E402

class Mixture:
    """A mixture-of-Gaussians policy head over an MLP: ``heads(x)`` -> (logits (N, K), loc
    (N, K, A), log-scale (N, K, A)); ``mode(x)`` the squashed mean of each row's heaviest
    component."""

    def __init__(self, n_in: int, n_act: int, components: int, hidden: list[int], mean, std):
        import torch

        sizes = [n_in, *hidden]
        layers = []
        for a, b in zip(sizes, sizes[1:]):
            layers += [torch.nn.Linear(a, b), torch.nn.ReLU()]
        self.K, self.A = components, n_act
        self.net = torch.nn.Sequential(*layers, torch.nn.Linear(sizes[-1], components * (1 + 2 * n_act)))
        self.mean, self.std = mean, std

    def heads(self, x):
        out = self.net((x - self.mean) / self.std)
        K, A = self.K, self.A
        return out[:, :K], out[:, K:K + K * A].reshape(-1, K, A), out[:, K + K * A:].reshape(-1, K, A).clamp(-7.0, 2.0)

    def nll(self, x, z):
        import torch

        logits, loc, log_scale = self.heads(x)
        per = (-log_scale - 0.5 * ((z[:, None, :] - loc) / log_scale.exp()) ** 2 - 0.5 * math.log(2 * math.pi)).sum(-1)
        return -torch.logsumexp(torch.log_softmax(logits, -1) + per, -1).mean()

    def mode(self, x):
        import torch

        with torch.no_grad():
            logits, loc, _ = self.heads(torch.as_tensor(x, dtype=torch.float32))
            k = logits.argmax(-1)
            return torch.tanh(loc[torch.arange(len(k)), k]).numpy()


def main(argv=None) -> None:
    import numpy as np
    import torch

    from billiards import domain, offline
    from billiards.bench import evaluate
    from billiards.physics import PRESETS, simulate_batch
    from billiards.physics.noise import NOISE_PRESETS

    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="a built dataset's folder (datasets/<noise>-<dataset>)")
    parser.add_argument("--components", type=int, nargs="+", default=[1, 8])
    parser.add_argument("--hidden", type=int, nargs="+", default=[512, 512, 512])
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--batch", type=int, default=512)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--held-out", type=int, default=4000, help="the dataset's last shots, held out (whole innings)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args(argv)
    if min(args.components) < 1 or args.epochs < 1 or args.held_out < offline.SHOTS or args.held_out % offline.SHOTS:
        parser.error("--components and --epochs must be >= 1, --held-out a positive multiple of 10")
    manifest = json.loads((args.dataset / "dataset.json").read_text())
    params, noise = PRESETS[manifest["physics"]], NOISE_PRESETS[manifest["noise"]]
    data = offline.transitions(args.dataset, "aim_features")
    obs, act = data["observation"], data["action"]
    n = obs.shape[0] - args.held_out
    x_train, z_train = obs[:n], torch.atanh(act[:n])  # the actions lie offline.EDGE inside the box: atanh is finite
    x_test = obs[n:].numpy()
    tables = domain.observed_positions(x_test)
    mean, std = x_train.mean(0), x_train.std(0) + 1e-6

    def scored(x) -> float:
        raw = domain.raw_action(x, tables, params.ball_radius, constrain_aim=True, normalized=True)
        if not noise.is_exact:
            raw = noise.apply(raw, noise.draw((len(raw),), np.random.default_rng(1)), params)
        return float(simulate_batch(tables, raw, params).score.mean())

    record = {"command": "python benchmarks/offline_bc.py " + " ".join(sys.argv[1:] if argv is None else argv),
              "commit": git_commit(), "dataset_id": manifest["dataset_id"], "train_shots": n,
              "held_out_shots": args.held_out, "label_scored": scored(act[n:].numpy().astype(np.float64)),
              "hidden": args.hidden, "epochs": args.epochs, "runs": []}
    print(f"{manifest['dataset_id']}: {n:,} training shots; the labels on the held-out tables score "
          f"{record['label_scored']:.1%}", flush=True)
    for K in args.components:
        torch.manual_seed(0)
        policy = Mixture(obs.shape[1], act.shape[1], K, args.hidden, mean, std)
        opt = torch.optim.Adam(policy.net.parameters(), lr=args.lr)
        per_epoch = n // args.batch
        sched = torch.optim.lr_scheduler.OneCycleLR(opt, args.lr, total_steps=args.epochs * per_epoch)
        gen = torch.Generator().manual_seed(0)
        history, cpu = [], time.process_time()
        for epoch in range(args.epochs):
            perm, total = torch.randperm(n, generator=gen), 0.0
            for i in range(per_epoch):
                j = perm[i * args.batch:(i + 1) * args.batch]
                loss = policy.nll(x_train[j], z_train[j])
                opt.zero_grad()
                loss.backward()
                opt.step()
                sched.step()
                total += loss.item()
            history.append({"epoch": epoch + 1, "nll": round(total / per_epoch, 4), "held_out_scored": scored(policy.mode(x_test))})
            print(f"K={K} epoch {epoch + 1}/{args.epochs}: nll {history[-1]['nll']:.3f}, its shot scores "
                  f"{history[-1]['held_out_scored']:.1%} of the held-out tables", flush=True)
        train_cpu = time.process_time() - cpu

        track = offline.IQL_TRACK[manifest["noise"]]
        card = evaluate(offline.space_agent(policy.mode, "aim_features", f"bc:mixture{K}", offline.track_radius(track)), track,
                        progress=False)
        record["runs"].append({"components": K, "train_cpu_seconds": round(train_cpu, 1), "history": history,
                               "track": track, "success_per_shot": card["success_per_shot"],
                               "points_per_inning": card["points_per_inning"]})
        print(f"K={K}: {track} {card['success_per_shot']['mean']:.1%} per shot {card['success_per_shot']['ci95']}", flush=True)
        write_json(args.out, record)


if __name__ == "__main__":
    main()
