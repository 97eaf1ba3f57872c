"""SAC training throughput on this CPU: gradient updates/s and collected env frames/s.

Compares the chosen defaults of ``conf/`` (``algo=sac env=aim_features``) with the
256x256 / batch-256 / UTD-1 / one-env baseline (the paper's stable-baselines3-like setup), in
the same process, alternating the two so that both see the same machine load:

* ``updates/s``: ``agent.update(rb.sample())`` on a replay buffer pre-filled with env frames;
* ``frames/s``: the TorchRL Collector stepping the batched env with the exploration policy,
  frames written to the replay buffer, no updates;
* ``train frames/s``: the two combined at the config's UTD (updates per frame), i.e. how fast
  training advances through its budget; and the implied wall time of 400k and 1M frames.

    python benchmarks/train_throughput.py                     # 1 thread, ~1 minute
    python benchmarks/train_throughput.py --seconds 5 --repeats 3 --threads 1
    python benchmarks/train_throughput.py --extra "algo.hidden_sizes=[64,64] algo.batch_size=1024"
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
BASELINE = ["algo.hidden_sizes=[256,256]", "algo.batch_size=256", "algo.utd=1.0", "env.num_envs=1"]


def compose(overrides: list[str]):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    import billiards.rl.config  # noqa: F401  (schema + resolvers)

    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        return hydra_compose("config", overrides=["algo=sac", "env=aim_features", *overrides])


class Bench:
    """Agent, env, buffer and collector of one config, ready to be timed."""

    def __init__(self, cfg, prefill: int = 5_000):
        import torch
        from torchrl.collectors import Collector
        from torchrl.data import LazyTensorStorage, RandomSampler, ReplayBuffer

        from billiards.rl.learners import make_agent
        from billiards.rl.train import make_train_env

        self.cfg = cfg
        self.env = make_train_env(cfg, seed=0)
        obs_dim = self.env.observation_spec_unbatched["observation"].shape[-1]
        self.agent = make_agent(cfg.algo, obs_dim, self.env.action_spec_unbatched)
        self.agent.set_warmup(False)
        self.rb = ReplayBuffer(storage=LazyTensorStorage(1_000_000), sampler=RandomSampler(), batch_size=cfg.algo.batch_size)
        fpb = cfg.algo.frames_per_batch or cfg.env.num_envs
        self.collector = Collector(self.env, self.agent.explore, frames_per_batch=fpb, total_frames=-1,
                                   trust_policy=True, auto_register_policy_transforms=False)
        self.batches = iter(self.collector)
        with torch.no_grad():
            while len(self.rb) < prefill:
                self.rb.extend(next(self.batches).reshape(-1).select(*self.agent.replay_keys))

    def updates_per_s(self, seconds: float) -> float:
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            self.agent.update(self.rb.sample())
            n += 1
        return n / (time.perf_counter() - t0)

    def frames_per_s(self, seconds: float) -> float:
        n, t0 = 0, time.perf_counter()
        while time.perf_counter() - t0 < seconds:
            data = next(self.batches)
            self.rb.extend(data.reshape(-1).select(*self.agent.replay_keys))
            n += data.numel()
        return n / (time.perf_counter() - t0)

    def close(self) -> None:
        self.collector.shutdown()


def describe(cfg) -> str:
    a = cfg.algo
    return (f"{'x'.join(map(str, a.hidden_sizes))} batch {a.batch_size} UTD {a.utd:g} "
            f"envs {cfg.env.num_envs} threads {cfg.threads}")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="seconds per measurement")
    parser.add_argument("--repeats", type=int, default=3, help="alternating repetitions (median reported)")
    parser.add_argument("--threads", type=int, default=1, help="torch/numba threads (default 1, as in training)")
    parser.add_argument("--extra", default="", help="extra overrides for the chosen config, space separated")
    args = parser.parse_args(argv)

    from billiards.device import set_threads

    set_threads(args.threads)
    configs = {
        "baseline (paper-like)": compose(BASELINE + [f"threads={args.threads}"]),
        "chosen defaults": compose([f"threads={args.threads}", *args.extra.split()]),
    }
    benches = {name: Bench(cfg) for name, cfg in configs.items()}
    ups = {name: [] for name in benches}
    fps = {name: [] for name in benches}
    for _ in range(args.repeats):
        for name, bench in benches.items():
            ups[name].append(bench.updates_per_s(args.seconds))
            fps[name].append(bench.frames_per_s(args.seconds / 2))
    for bench in benches.values():
        bench.close()

    print(f"SAC training throughput, env=aim_features, {args.threads} thread(s), median of {args.repeats} alternating "
          f"runs of {args.seconds:g}s; python {sys.version.split()[0]}")
    header = (f"{'config':<24} {'settings':<46} {'updates/s':>10} {'samples/s':>10} {'frames/s':>10} "
              f"{'train fr/s':>10} {'400k':>7} {'1M':>7}")
    print(header)
    print("-" * len(header))
    for name, cfg in configs.items():
        u, f = statistics.median(ups[name]), statistics.median(fps[name])
        train_fps = 1.0 / (1.0 / f + cfg.algo.utd / u)  # seconds per frame: collect it + utd updates
        h400k, h1m = (frames / train_fps / 3600 for frames in (4e5, 1e6))
        print(f"{name:<24} {describe(cfg):<46} {u:>10.1f} {u * cfg.algo.batch_size:>10.0f} {f:>10.0f} "
              f"{train_fps:>10.1f} {h400k:>6.2f}h {h1m:>6.2f}h")
    print("\nsamples/s = updates/s x batch; train fr/s = frames per second of training at the config's UTD; "
          "400k / 1M: implied hours for the paper's budgets (evaluation excluded).")


if __name__ == "__main__":
    main()
