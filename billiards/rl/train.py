"""The training loop behind ``train.py``: SAC / TD3 (off-policy, replay) and PPO (on-policy).

One env frame is one shot of one of the ``env.num_envs`` innings played side by side, the
paper's "step". Off-policy: a TorchRL :class:`~torchrl.collectors.Collector` steps the
batched env with the exploration policy (uniform random actions for
``budget.init_random_steps`` frames), every frame goes into a replay buffer
(:class:`~torchrl.data.LazyTensorStorage`, uniform sampling), and after the warm-up
``algo.utd`` gradient updates are made per collected frame. PPO: rollouts of
``algo.frames_per_batch`` frames, GAE, ``algo.epochs`` passes of minibatches.

Along the way: a metric row every ``budget.log_every`` frames (metrics.csv, wandb), an
evaluation with the unified protocol every ``budget.eval_every`` frames
(eval_history.jsonl), a checkpoint every ``budget.checkpoint_every`` frames; at the end the
final evaluation (eval.json, eval_<start>.json for further starts), summary.json and a last
checkpoint. ``resume=<run dir>`` rebuilds everything from the checkpoint and goes on.
"""

from __future__ import annotations

import json
import logging
import math
import os
import random
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from billiards.files import atomic_write_text
from billiards.physics.config import params_from_config, physics_record
from billiards.physics.noise import noise_from_config, noise_record
from billiards.physics.warmup import warm_up

from .checkpoint import CheckpointError, load_checkpoint, rng_state, save_checkpoint, set_rng_state
from .config import (
    ALGO_SCHEMAS,
    CONFIG_FILE,
    EVAL_FILE,
    EVAL_HISTORY_FILE,
    Config,
    ConfigError,
    env_paradigm,
    resolve_rm_model,
    validate,
    with_physics,
)
from .metrics import MetricLogger, eval_row

log = logging.getLogger(__name__)

# Keys taken from the command line when resuming (everything else comes from the checkpoint).
RUNTIME_KEYS = ("threads", "progress", "compile", "budget.kill_after_checkpoint")
# Keys a resume takes from the command line only when given there (else the checkpoint's value):
# a killed run can be given a CPU-time limit, e.g. to end it within one CPU hour.
RESUME_KEYS = ("budget.cpu_minutes",)


# ----------------------------------------------------------------------------- setup helpers


def set_threads(n: int) -> None:
    """torch intra-op threads and numba's (the simulator's) threads for this process."""
    torch.set_num_threads(n)
    import numba

    numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def env_kwargs(cfg) -> dict[str, Any]:
    """make_env keyword arguments of the training env (shaping included)."""
    return dict(
        paradigm=env_paradigm(cfg.env.paradigm),
        max_shots=cfg.env.max_shots,
        constrain_aim=cfg.env.constrain_aim,
        extra_features=cfg.env.extra_features,
        foul_penalty=cfg.shaping.foul_penalty,
        gentle=cfg.shaping.gentle,
        near_miss=cfg.shaping.near_miss,
        near_miss_sigma=cfg.shaping.near_miss_sigma,
        gentle_kind=cfg.shaping.gentle_kind,
        rm=cfg.shaping.rm,
        rm_model=str(resolve_rm_model(cfg.shaping.rm_model)) if cfg.shaping.rm else None,
        params=params_from_config(cfg.physics),
        noise=noise_from_config(cfg.get("noise")),
    )


def make_train_env(cfg, seed: int):
    from billiards.envs import make_env

    return make_env(cfg.env.num_envs, seed=seed, **env_kwargs(cfg))


def rack_rng(env) -> np.random.Generator:
    """The numpy Generator the training env draws its racks from."""
    return env.base_env.rng


def evaluate_policy(cfg, policy, n_innings: int, start: str):
    from billiards.evaluation import evaluate

    return evaluate(
        policy,
        n_innings=n_innings,
        max_shots=cfg.eval.max_shots,
        start=start,
        seed=cfg.eval.seed,
        constrain_aim=cfg.env.constrain_aim,
        extra_features=cfg.env.extra_features,
        env_kwargs=dict(params=params_from_config(cfg.physics)),
        noise=noise_from_config(cfg.get("noise")),
    )


def eval_starts(cfg) -> list[str]:
    """cfg.eval.starts as plain strings (the first is the primary metric)."""
    return [getattr(s, "value", str(s)) for s in cfg.eval.starts]


def _plain(cfg) -> dict:
    return OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)


def _typed(container: dict) -> DictConfig:
    """A saved (plain) config merged back into the schema, so enums and types are checked and
    keys added to the schema after the run started (e.g. ``algo.actor_ema``) take their
    documented defaults."""
    schema = OmegaConf.structured(Config)
    container = with_physics(container)
    algo = (container.get("algo") or {}).get("name")
    if algo in ALGO_SCHEMAS:
        schema.algo = OmegaConf.structured(ALGO_SCHEMAS[algo])
    return OmegaConf.merge(schema, container)


def _command_line_overrides() -> list[str]:
    """This invocation's Hydra task overrides (empty outside a Hydra app)."""
    try:
        from hydra.core.hydra_config import HydraConfig

        return list(HydraConfig.get().overrides.task) if HydraConfig.initialized() else []
    except ValueError:
        return []


def resume_config(saved: dict, current: DictConfig, overrides: list[str] | None = None) -> DictConfig:
    """The checkpoint's config, with RUNTIME_KEYS from the command line, and RESUME_KEYS where
    ``overrides`` (default: this invocation's command line) set them. Warns about other
    command-line overrides, which a resume ignores."""
    if overrides is None:
        overrides = _command_line_overrides()
    cfg = _typed(saved)
    for key in RUNTIME_KEYS:
        OmegaConf.update(cfg, key, OmegaConf.select(current, key), merge=False)
    keys = [o.split("=", 1)[0].lstrip("+~") for o in overrides]
    for key in RESUME_KEYS:
        if key in keys:
            OmegaConf.update(cfg, key, OmegaConf.select(current, key), merge=False)
            log.info("resume: %s=%s from the command line", key, OmegaConf.select(current, key))
    cfg.resume = current.resume
    ignored = [o for o, key in zip(overrides, keys) if key not in RUNTIME_KEYS + RESUME_KEYS + ("resume",)]
    if ignored:
        log.warning("resume: the run keeps its checkpointed config; ignoring overrides %s", ignored)
    return cfg


def finished_result(ckpt: dict[str, Any], cfg: DictConfig, run_dir: Path) -> tuple[float, int] | None:
    """``(final mean points per inning, frames)`` if the checkpoint is that of a finished run
    -- its budget (budget.total_steps, or budget.cpu_minutes as now configured) spent, its
    final evaluation at that step recorded, and ``eval.json`` in ``run_dir`` -- else None."""
    c, b = ckpt["counters"], cfg.budget
    frames = int(c["frames"])
    spent = frames >= b.total_steps or (b.cpu_minutes > 0 and float(c["cpu_seconds"]) >= 60.0 * b.cpu_minutes)
    finals = [h for h in ckpt.get("eval_history") or [] if h.get("final") and h.get("step") == frames]
    if spent and finals and (Path(run_dir) / EVAL_FILE).is_file():
        return float(finals[0]["eval_mean"]), frames  # the first start is the primary one
    return None


# ----------------------------------------------------------------------------- the trainer


class Trainer:
    """One training run in ``run_dir``; :meth:`run` trains to the budget and returns the final
    mean points per inning of the primary evaluation start."""

    def __init__(self, cfg: DictConfig, run_dir: Path):
        self.run_dir = Path(run_dir)
        ckpt = None
        if cfg.resume:
            ckpt = load_checkpoint(cfg.resume)
            if Path(cfg.resume).resolve() != self.run_dir.resolve():
                log.info("resume: continuing %s (this invocation's own dir is %s)", cfg.resume, self.run_dir)
                self.run_dir = Path(cfg.resume)
            cfg = resume_config(ckpt["config"], cfg)
        validate(cfg)
        self.cfg = cfg
        self.algo = cfg.algo.name
        self.off_policy = self.algo in ("sac", "td3")
        # Resuming a finished run builds and writes nothing: run() says so and returns its result.
        self.finished = finished_result(ckpt, cfg, self.run_dir) if ckpt is not None else None
        if self.finished is not None:
            return
        set_threads(cfg.threads)
        seed_everything(cfg.seed)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        if ckpt is None:
            atomic_write_text(self.run_dir / CONFIG_FILE, OmegaConf.to_yaml(_plain(cfg)))

        from billiards.rl.agents import make_agent

        self.env = make_train_env(cfg, seed=cfg.seed)
        obs_dim = self.env.observation_spec_unbatched["observation"].shape[-1]
        self.agent = make_agent(cfg.algo, obs_dim, self.env.action_spec_unbatched)
        if cfg.compile:
            self.agent.compile()
        from billiards.rl.curriculum import make_curriculum

        self.curriculum = make_curriculum(cfg, self.agent)
        self.stage: int | None = None
        self.stage_log: list[dict] = []  # {"stage", "step", "free"} at each stage entry

        b = cfg.budget
        self.frames = 0
        self.owed = 0.0  # fractional gradient updates carried over (off-policy)
        self.train_seconds = 0.0  # wall-clock and CPU (process) seconds of earlier processes of this run
        self.cpu_seconds = 0.0
        self.next_log = b.log_every
        self.next_eval = b.eval_every or math.inf
        self.next_ckpt = b.checkpoint_every or math.inf
        self.n_ckpt = 0
        self.eval_history: list[dict] = []
        self.latest_eval: float | None = None
        self.rb = self._make_buffer() if self.off_policy else None
        wandb_id = None
        if ckpt is not None:
            wandb_id = self._restore(ckpt)
        metric_names = self.agent.metric_names + (("stage",) if self.curriculum else ())
        self.logger = MetricLogger(cfg, self.run_dir, metric_names,
                                   resume_step=self.frames if ckpt is not None else None, wandb_id=wandb_id)
        if ckpt is not None:  # the history file reads as one run, like metrics.csv
            self._write_eval_history()
            self.stage_log = list(ckpt.get("stage_log") or [])
        self._update_stage()
        self._window_reset()

    # -------------------------------------------------------------- curriculum

    def _update_stage(self) -> None:
        """Frees the action dimensions of the curriculum stage in force at ``self.frames``
        (a no-op without a curriculum). The agent -- networks, optimizer, replay buffer --
        carries over unchanged: the warm start."""
        if self.curriculum is None:
            return
        curriculum, hold = self.curriculum
        stage = curriculum.stage_at(self.frames)
        if stage == self.stage:
            return
        self.stage = stage
        hold.set_free(curriculum.free_dims(stage))
        entry = curriculum.describe()[stage] | {"step": self.frames}
        if not self.stage_log or self.stage_log[-1]["stage"] != stage:
            self.stage_log.append(entry)
        log.info("curriculum: stage %d from step %d, free action dims %s", stage, self.frames, entry["free"])

    # -------------------------------------------------------------- buffer and state

    def _make_buffer(self):
        from torchrl.data import LazyTensorStorage, RandomSampler, ReplayBuffer

        capacity = min(self.cfg.algo.buffer_size, self.cfg.budget.total_steps)
        return ReplayBuffer(storage=LazyTensorStorage(capacity), sampler=RandomSampler(),
                            batch_size=self.cfg.algo.batch_size)

    def _state(self) -> dict[str, Any]:
        buffer = None
        if self.rb is not None and self.cfg.checkpoint.save_buffer and len(self.rb):
            n = len(self.rb)  # a TensorDict is no plain type: its nested dict of tensors and its length
            buffer = {"data": self.rb.storage[:n].clone().to_dict(), "rows": n, "writer": self.rb.writer.state_dict()}
        return {
            "config": _plain(self.cfg),
            "agent": self.agent.state_dict(),
            "agent_extra": self.agent.state_dict_extra(),
            "buffer": buffer,
            "counters": {
                "frames": self.frames,
                "owed": self.owed,
                "train_seconds": self._times()[0],
                "cpu_seconds": self._times()[1],
                "next_log": self.next_log,
                "next_eval": self.next_eval,
                "next_ckpt": self.next_ckpt,
            },
            "eval_history": self.eval_history,
            "rng": rng_state(rack_rng(self.env)),
            "wandb_id": self.logger.wandb_id,
            "stage_log": self.stage_log,
        }

    def _restore(self, ckpt: dict[str, Any]) -> str | None:
        try:
            self.agent.load_state_dict(ckpt["agent"])
            self.agent.load_state_dict_extra(ckpt["agent_extra"])
        except (RuntimeError, KeyError, ValueError) as err:
            raise CheckpointError(f"cannot resume: the checkpoint's networks do not fit this config ({err})") from None
        c = ckpt["counters"]
        self.frames, self.owed = int(c["frames"]), float(c["owed"])
        self.train_seconds, self.cpu_seconds = float(c["train_seconds"]), float(c["cpu_seconds"])
        self.next_log, self.next_eval, self.next_ckpt = c["next_log"], c["next_eval"], c["next_ckpt"]
        self.eval_history = list(ckpt.get("eval_history") or [])
        if self.eval_history:
            self.latest_eval = self.eval_history[-1]["eval_mean"]
        buffer = ckpt.get("buffer")
        if self.rb is not None and buffer is not None:
            from tensordict import TensorDict

            self.rb.extend(TensorDict(buffer["data"], batch_size=[buffer["rows"]]))
            self.rb.writer.load_state_dict(buffer["writer"])
        elif self.rb is not None:
            log.warning("resume: the checkpoint has no replay buffer (checkpoint.save_buffer=false); refilling from scratch")
        set_rng_state(ckpt["rng"], rack_rng(self.env))
        log.info("resumed from %s at %d frames, %d updates", self.run_dir, self.frames, self.agent.n_updates)
        return ckpt.get("wandb_id")

    def _checkpoint(self) -> None:
        save_checkpoint(self.run_dir, self._state())
        self.n_ckpt += 1
        kill = self.cfg.budget.kill_after_checkpoint
        if kill and self.n_ckpt >= kill:
            log.warning("budget.kill_after_checkpoint=%d: killing the run (SIGKILL) after checkpoint %d", kill, self.n_ckpt)
            self.logger.close()
            sys.stdout.flush()
            sys.stderr.flush()
            os.kill(os.getpid(), signal.SIGKILL)

    def _write_eval_history(self) -> None:
        text = "".join(json.dumps(e) + "\n" for e in self.eval_history)
        atomic_write_text(self.run_dir / EVAL_HISTORY_FILE, text)

    # -------------------------------------------------------------- bookkeeping

    def _times(self) -> tuple[float, float]:
        """Training wall-clock and CPU seconds so far, over all processes of this run."""
        return (self.train_seconds + time.perf_counter() - self._t0,
                self.cpu_seconds + time.process_time() - self._c0)

    def _cpu_spent(self) -> bool:
        """True once budget.cpu_minutes (if set) of process CPU time are used up."""
        limit = self.cfg.budget.cpu_minutes
        return bool(limit) and self._times()[1] >= 60.0 * limit

    def _finished(self) -> bool:
        """The training budget is spent: budget.total_steps frames or budget.cpu_minutes."""
        return self.frames >= self.cfg.budget.total_steps or self._cpu_spent()

    def _window_reset(self) -> None:
        self._w_frames, self._w_updates, self._w_t = 0, self.agent.n_updates, time.perf_counter()
        self._w_reward = self._w_score = self._w_foul = 0.0
        self._w_metrics: Any = None

    def _window_add(self, data) -> None:
        nxt = data.get("next")
        self._w_frames += data.numel()
        self._w_reward += float(nxt.get("reward").sum())
        self._w_score += float(nxt.get("score").sum())
        self._w_foul += float(nxt.get("foul").sum())

    def _log_row(self) -> dict[str, Any]:
        dt = max(time.perf_counter() - self._w_t, 1e-9)
        n = max(self._w_frames, 1)
        wall, cpu = self._times()
        row = {
            "step": self.frames,
            "updates": self.agent.n_updates,
            "wall_time": round(wall, 3),
            "cpu_time": round(cpu, 3),
            "fps": round(self._w_frames / dt, 1),
            "ups": round((self.agent.n_updates - self._w_updates) / dt, 2),
            "train_reward": self._w_reward / n,
            "train_score_pct": 100.0 * self._w_score / n,
            "train_foul_pct": 100.0 * self._w_foul / n,
        }
        if self.stage is not None:
            row["stage"] = self.stage
        if self._w_metrics is not None:
            from billiards.rl.agents import metrics_of

            row.update(metrics_of(self._w_metrics, self.agent.metric_names))
        return row

    def _periodic(self, bar) -> None:
        b = self.cfg.budget
        if self.frames >= self.next_log:
            self.logger.log(self._log_row())
            self._window_reset()
            self.next_log = (self.frames // b.log_every + 1) * b.log_every
        done = self._finished()  # the final evaluation and checkpoint follow
        if self.frames >= self.next_eval and not done:
            self._evaluate(b.eval_innings, eval_starts(self.cfg)[0], final=False)
            self.next_eval = (self.frames // b.eval_every + 1) * b.eval_every
        if self.frames >= self.next_ckpt and not done:
            self.next_ckpt = (self.frames // b.checkpoint_every + 1) * b.checkpoint_every
            self._checkpoint()
        postfix = {"ups": f"{(self.agent.n_updates - self._w_updates) / max(time.perf_counter() - self._w_t, 1e-9):.0f}"}
        if self.latest_eval is not None:
            postfix["eval"] = f"{self.latest_eval:.2f}"
        bar.set_postfix(postfix, refresh=False)

    def _evaluate(self, n_innings: int, start: str, final: bool):
        """Evaluates and records the agent's eval policy; with an averaged actor
        (algo.actor_ema > 0) also the live actor, recorded beside it under ``live_*`` keys.
        Returns ``(result, live result or None)``."""
        result = evaluate_policy(self.cfg, self.agent.eval_policy, n_innings, start)
        live = None
        if self.agent.eval_policy is not self.agent.policy:
            live = evaluate_policy(self.cfg, self.agent.policy, n_innings, start)
        self._record_eval(result, final, live)
        return result, live

    def _record_eval(self, result, final: bool, live=None) -> None:
        wall, cpu = self._times()
        entry = {
            "step": self.frames,
            "updates": self.agent.n_updates,
            "wall_time": round(wall, 3),
            "cpu_time": round(cpu, 3),
            "final": final,
            "start": result.start,
            "n_innings": result.n_innings,
            **{k: v for k, v in eval_row(result).items()},
        }
        if live is not None:
            entry |= {f"live_{k}": v for k, v in eval_row(live).items()}
        self.eval_history.append(entry)
        self._write_eval_history()
        self.latest_eval = result.mean
        self.logger.log({k: entry[k] for k in ("step", "updates", "wall_time", "cpu_time")} | eval_row(result))
        log.info("eval @ %d frames: %s", self.frames, result.summary())
        if live is not None:
            log.info("eval @ %d frames, live actor: %s", self.frames, live.summary())

    # -------------------------------------------------------------- loops

    def _collector(self, policy, frames_per_batch: int):
        from torchrl.collectors import Collector

        remaining = self.cfg.budget.total_steps - self.frames
        total = math.ceil(remaining / frames_per_batch) * frames_per_batch
        return Collector(self.env, policy, frames_per_batch=frames_per_batch, total_frames=total,
                         trust_policy=True, auto_register_policy_transforms=False)

    def _off_policy(self, bar) -> None:
        a, b = self.cfg.algo, self.cfg.budget
        fpb = a.frames_per_batch or self.cfg.env.num_envs
        self.agent.set_warmup(self.frames < b.init_random_steps)
        collector = self._collector(self.agent.explore, fpb)
        keys = self.agent.replay_keys
        try:
            for data in collector:
                n = data.numel()
                self.frames += n
                self.rb.extend(data.reshape(-1).select(*keys))
                self._window_add(data)
                if self.frames >= b.init_random_steps:
                    self.owed += a.utd * n
                    k = int(self.owed)
                    self.owed -= k
                    for _ in range(k):
                        self._w_metrics = self.agent.update(self.rb.sample())
                self.agent.set_warmup(self.frames < b.init_random_steps)
                self._update_stage()
                bar.update(n)
                self._periodic(bar)
                if self._cpu_spent():
                    break
        finally:
            collector.shutdown()

    def _ppo(self, bar) -> None:
        a = self.cfg.algo
        collector = self._collector(self.agent.explore, a.frames_per_batch)
        try:
            for data in collector:
                n = data.numel()
                self.frames += n
                self._window_add(data)
                for _ in range(a.epochs):
                    flat = self.agent.advantage(data).reshape(-1)
                    perm = torch.randperm(n)
                    for i in range(0, n - a.minibatch_size + 1, a.minibatch_size):
                        self._w_metrics = self.agent.update(flat[perm[i:i + a.minibatch_size]])
                bar.update(n)
                self._periodic(bar)
                if self._cpu_spent():
                    break
        finally:
            collector.shutdown()

    def run(self) -> float:
        if self.finished is not None:
            mean, frames = self.finished
            log.warning("resume: %s is already finished (%d frames, final evaluation in %s: %.3f points per inning); "
                        "nothing to do, nothing changed. Start a new run to train further.",
                        self.run_dir, frames, EVAL_FILE, mean)
            return mean
        cfg, b = self.cfg, self.cfg.budget
        params = params_from_config(cfg.physics)
        log.info("output: %s (%s, %s steps, physics %s)", self.run_dir, self.algo, f"{b.total_steps:,}", params.describe())
        warm_up(params, log=log.info)
        self._t0, self._c0 = time.perf_counter(), time.process_time()
        interactive = sys.stderr.isatty()
        with tqdm(total=b.total_steps, initial=self.frames, unit="shot", unit_scale=True, dynamic_ncols=True,
                  mininterval=1.0 if interactive else 30.0, disable=not cfg.progress, file=sys.stderr,
                  desc=f"{self.algo} {self.run_dir.name}", smoothing=0.05) as bar:
            if not self._finished():
                (self._off_policy if self.off_policy else self._ppo)(bar)
            results = self._final_eval()
            bar.set_postfix(eval=f"{results[0].mean:.2f}")  # the final evaluation, not the last periodic one
            save_checkpoint(self.run_dir, self._state())
        self.logger.close()
        log.info("done: %s, summary.json and checkpoint.pt in %s", EVAL_FILE, self.run_dir)
        return results[0].mean

    def _final_eval(self):
        cfg = self.cfg
        if self._w_frames:
            self.logger.log(self._log_row())
        results, lives = [], {}
        for i, start in enumerate(eval_starts(cfg)):
            result, live = self._evaluate(cfg.budget.final_eval_innings, start, final=True)
            results.append(result)
            if live is not None:
                lives[start] = eval_row(live)
            result.to_json(self.run_dir / (EVAL_FILE if i == 0 else f"eval_{start}.json"))
        train_seconds, cpu_seconds = self._times()
        summary = {
            "algo": self.algo,
            "table": cfg.table,
            "seed": cfg.seed,
            "frames": self.frames,
            "updates": self.agent.n_updates,
            **physics_record(params_from_config(cfg.physics)),
            **noise_record(noise_from_config(cfg.get("noise"))),
            "stopped_by": "total_steps" if self.frames >= cfg.budget.total_steps else "cpu_minutes",
            "train_seconds": round(train_seconds, 2),
            "cpu_seconds": round(cpu_seconds, 2),
            "frames_per_second": round(self.frames / max(train_seconds, 1e-9), 1),
            "updates_per_second": round(self.agent.n_updates / max(train_seconds, 1e-9), 2),
            "eval": {r.start: eval_row(r) for r in results},
        }
        if lives:  # eval is the averaged actor's (algo.actor_ema); this, the live actor's
            summary["eval_live"] = lives
        if self.curriculum is not None:
            summary["curriculum"] = self.stage_log
        atomic_write_text(self.run_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
        for r in results:
            log.info("final eval (%s start): %s", r.start, r.summary())
        return results


def train(cfg: DictConfig, run_dir: str | Path | None = None) -> float:
    """Train as configured; returns the final mean points per inning (primary eval start).

    ``run_dir`` defaults to Hydra's output dir of the job (or the resumed run's dir).
    """
    if run_dir is None:
        from hydra.core.hydra_config import HydraConfig

        run_dir = HydraConfig.get().runtime.output_dir
    try:
        trainer = Trainer(cfg, Path(run_dir))
    except (CheckpointError, ConfigError) as err:
        raise SystemExit(f"Error: {err}") from None
    return trainer.run()


__all__ = ["Trainer", "train"]
