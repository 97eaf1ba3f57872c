"""The training loops behind ``train.py``: SAC / TD3 (off-policy, replay) and PPO (on-policy).

One env frame is one shot of one of the ``env.num_envs`` innings played side by side, the
paper's "step". A run is read in three places:

* :func:`make_run` builds its parts -- the env (the simulator, on the CPU), the agent and the
  replay buffer (on ``device``), the metric logger, the curriculum -- and its
  :class:`~billiards.rl.checkpoint.RunState`, fresh or restored from ``resume=<run dir>``;
* :func:`train_off_policy` (SAC, TD3) and :func:`train_ppo` are the loops, one each, top to
  bottom. Off-policy: a TorchRL :class:`~torchrl.collectors.Collector` steps the batched env
  with the exploration policy (uniform random actions for ``budget.init_random_steps``
  frames), every frame goes into the replay buffer and after the warm-up ``algo.utd``
  gradient updates are made per collected frame. PPO: rollouts of ``algo.frames_per_batch``
  frames, GAE, ``algo.epochs`` passes of minibatches;
* :func:`periodic` is the cadence both loops call once per batch: a metric row every
  ``budget.log_every`` frames (metrics.csv, wandb, TensorBoard), an evaluation with the
  unified protocol every ``budget.eval_every`` (eval_history.jsonl), a checkpoint every
  ``budget.checkpoint_every``; :func:`finish` makes the final evaluation (eval.json,
  eval_<start>.json for further starts), summary.json and the last checkpoint.

A killed run keeps its last checkpoint and goes on from it with ``resume=<run dir>``; a checkpoint
holds the collector's state between two batches and every random generator, so the resumed run
ends exactly as the uninterrupted one would have.
"""

from __future__ import annotations

import json
import logging
import math
import random
import signal
import sys
from collections.abc import Iterable, Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tqdm import tqdm

from billiards import compat
from billiards.app_config import RESUME_AUTO
from billiards.device import resolve_device, set_threads
from billiards.files import CHECKPOINT_FILE, RunLockedError, atomic_write_text, display_path, run_lock
from billiards.physics.config import params_from_config, physics_record
from billiards.physics.noise import noise_from_config, noise_record
from billiards.physics.warmup import warm_up
from billiards.provenance import record_start

from .learners import OFF_POLICY, Agent, make_agent
from .checkpoint import CheckpointError, RunState, load_checkpoint, save_checkpoint
from .config import (
    ALGO_SCHEMAS,
    CONFIG_FILE,
    REPLAY,
    EVAL_FILE,
    EVAL_HISTORY_FILE,
    METRICS_FILE,
    Config,
    ConfigError,
    env_options,
)
from .curriculum import Stages, make_curriculum
from .metrics import MetricLogger, Window, eval_row
from .validation import validate

log = logging.getLogger(__name__)

# Keys taken from the command line when resuming (everything else comes from the checkpoint).
RUNTIME_KEYS = Config.RUNTIME
# Keys a resume takes from the command line only when given there (else the checkpoint's value):
# a killed run can be given a CPU-time limit, e.g. to end it within one CPU hour.
RESUME_KEYS = ("budget.cpu_minutes",)

__all__ = ["RESUME_KEYS", "RUNTIME_KEYS", "OnDevice", "Run", "finish", "finished_line", "load_run_config", "make_collector",
           "make_replay_buffer", "make_run", "periodic", "resume_state", "train", "train_off_policy", "train_ppo"]


# ----------------------------------------------------------------------------- setup helpers


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def make_train_env(cfg, seed: int):
    """The batched training env; it (the simulator) always runs on the CPU."""
    from billiards.envs import make_env

    return make_env(cfg.env.num_envs, env_options(cfg), seed=seed)


def env_rngs(env) -> dict[str, np.random.Generator]:
    """The numpy Generators the training env draws from: its racks (``"env"``) and its
    execution noise (``"env_noise"``)."""
    return {"env": env.base_env.rng, "env_noise": env.base_env.noise_rng}


def carrier_spec(env):
    """What the tensordict between two env steps holds of the env: its observation and done
    specs (a checkpoint's collector state must fit them)."""
    return env.full_observation_spec.clone().update(env.full_done_spec)


def evaluate_policy(cfg, policy, n_innings: int, start: str):
    from billiards.evaluation import evaluate_policy

    return evaluate_policy(
        policy,
        n_innings=n_innings,
        max_shots=cfg.eval.max_shots,
        start=start,
        seed=cfg.eval.seed,
        constrain_aim=cfg.env.constrain_aim,
        extra_features=cfg.env.extra_features,
        env_kwargs=dict(params=params_from_config(cfg.physics)),
        noise=noise_from_config(cfg.noise),
    )


def eval_starts(cfg) -> list[str]:
    """cfg.eval.starts as plain strings (the first is the primary metric)."""
    return [getattr(s, "value", str(s)) for s in cfg.eval.starts]


def _plain(cfg) -> dict:
    return OmegaConf.to_container(cfg, resolve=True, enum_to_str=True)


def _typed(container: dict) -> DictConfig:
    """A saved (plain) config brought to today's form (:func:`billiards.compat.upgrade_training_config`)
    and merged into the schema, so enums and types are checked and every key has its value."""
    schema = OmegaConf.structured(Config)
    container = compat.upgrade_training_config(container)
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


def finished_line(run_dir, frames: int, mean: float) -> str:
    """What a resume of a finished run says."""
    return (f"resume: {run_dir} is already finished ({frames} frames, final evaluation in {EVAL_FILE}: {mean:.3f} points "
            f"per inning); nothing to do, nothing changed. Start a new run to train further.")


def resume_state(run_dir: Path, config: DictConfig, finished: bool) -> str | None:
    """The directory check's look at the training run in ``run_dir`` before a resume
    (:class:`billiards.app_config.RunKind`): with ``finished``, the line :func:`train` would say
    if the run is finished (its checkpoint, budget and evaluation, as :func:`finished_result`
    reads them with this command line's ``budget.cpu_minutes``), else None; ValueError for a
    checkpoint that cannot be loaded."""
    if not finished or not (Path(run_dir) / EVAL_FILE).is_file():
        return None  # the checkpoint's presence is validate's; its contents are read by the run
    try:
        ckpt = load_checkpoint(run_dir)
    except CheckpointError as err:
        raise ValueError(str(err)) from None
    given = [str(o) for o in (OmegaConf.select(config, "hydra.overrides.task", default=None) or [])]
    try:
        cfg = resume_config(ckpt["config"], config, overrides=[o for o in given if o.split("=", 1)[0].lstrip("+~") in RESUME_KEYS])
        done = finished_result(ckpt, cfg, Path(run_dir))
    except Exception:  # a config the run itself reports on
        return None
    return None if done is None else finished_line(run_dir, done[1], done[0])


# ----------------------------------------------------------------------------- the run's parts


def make_replay_buffer(cfg, device: torch.device):
    """Uniform replay over the last ``algo.buffer_size`` frames (at most the budget), stored
    on ``device``."""
    from torchrl.data import LazyTensorStorage, RandomSampler, ReplayBuffer

    capacity = min(cfg.algo.buffer_size, cfg.budget.total_steps)
    return ReplayBuffer(storage=LazyTensorStorage(capacity, device=device), sampler=RandomSampler(),
                        batch_size=cfg.algo.batch_size)


def make_collector(run: Run, policy, frames_per_batch: int):
    """A Collector stepping the run's env (CPU) with ``policy`` (on the run's device) until
    the budget's frames are collected: each step's TensorDict crosses to the device and back
    once, and the batches it yields are stored on the device."""
    from torchrl.collectors import Collector

    remaining = run.cfg.budget.total_steps - run.state.frames
    total = math.ceil(remaining / frames_per_batch) * frames_per_batch
    return Collector(run.env, policy, frames_per_batch=frames_per_batch, total_frames=total,
                     env_device="cpu", policy_device=run.device, storing_device=run.device,
                     trust_policy=True, auto_register_policy_transforms=False)


class OnDevice(TensorDictModuleBase):
    """``policy`` (on ``device``) for an env on the CPU: each step's TensorDict goes to the
    device, the policy's outputs come back (used by evaluations; on the CPU, moves nothing)."""

    def __init__(self, policy: TensorDictModuleBase, device: torch.device):
        super().__init__()
        self.policy, self.device = policy, device
        self.in_keys, self.out_keys = list(policy.in_keys), list(policy.out_keys)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        return tensordict.update(self.policy(tensordict.to(self.device)).to("cpu"))


@dataclass
class Run:
    """One training run in ``run_dir``: what :func:`make_run` builds, what the loops use."""

    cfg: DictConfig
    run_dir: Path
    device: torch.device
    env: Any  # the batched TorchRL env (on the CPU)
    agent: Agent
    rb: Any  # the replay buffer (off-policy), None for PPO
    state: RunState
    logger: MetricLogger
    stages: Stages | None  # the curriculum, None without one
    window: Window
    collector: Any = None  # the running collector (while a loop collects), whose state checkpoints hold

    def budget_spent(self) -> bool:
        """The training budget is spent: budget.total_steps frames or budget.cpu_minutes."""
        return self.state.frames >= self.cfg.budget.total_steps or self.cpu_spent()

    def cpu_spent(self) -> bool:
        """True once budget.cpu_minutes (if set) of process CPU time are used up."""
        limit = self.cfg.budget.cpu_minutes
        return bool(limit) and self.state.times()[1] >= 60.0 * limit

    def update_stage(self) -> None:
        """Frees the action dimensions of the curriculum stage in force (no-op without one)."""
        if self.stages is not None:
            self.stages.update(self.state.frames, self.state.stage_log)

    def log_window(self) -> None:
        """A metric row of the frames since the last one."""
        stage = None if self.stages is None else self.stages.stage
        self.logger.log(self.window.row(self.state.frames, self.agent.n_updates, self.state.times(),
                                        self.agent.metric_names, stage))
        self.window.reset(self.agent.n_updates)

    def evaluate(self, n_innings: int, start: str, final: bool):
        """Evaluates and records the agent's eval policy; with an averaged actor
        (algo.actor_ema > 0) also the live actor, recorded beside it under ``live_*`` keys.
        Returns ``(result, live result or None)``."""
        agent = self.agent
        result = evaluate_policy(self.cfg, OnDevice(agent.eval_policy, self.device), n_innings, start)
        live = None
        if agent.eval_policy is not agent.policy:
            live = evaluate_policy(self.cfg, OnDevice(agent.policy, self.device), n_innings, start)
        wall, cpu = self.state.times()
        entry = {
            "step": self.state.frames,
            "updates": agent.n_updates,
            "wall_time": round(wall, 3),
            "cpu_time": round(cpu, 3),
            "final": final,
            "start": result.start,
            "n_innings": result.n_innings,
            **eval_row(result),
        }
        if live is not None:
            entry |= {f"live_{k}": v for k, v in eval_row(live).items()}
        self.state.eval_history.append(entry)
        write_eval_history(self.run_dir, self.state.eval_history)
        self.logger.log({k: entry[k] for k in ("step", "updates", "wall_time", "cpu_time")} | eval_row(result))
        log.info("eval @ %d frames: %s", self.state.frames, result.summary())
        if live is not None:
            log.info("eval @ %d frames, live actor: %s", self.state.frames, live.summary())
        return result, live

    def checkpoint(self) -> Path:
        """Writes checkpoint.pt: the run state with the config, agent, buffer, collector and RNGs."""
        state = self.state.capture(_plain(self.cfg), self.agent, self.rb, env_rngs(self.env), collector=self.collector,
                                   save_buffer=self.cfg.checkpoint.save_buffer, device=self.device)
        return save_checkpoint(self.run_dir, state)


def write_eval_history(run_dir: Path, history: list[dict]) -> None:
    atomic_write_text(run_dir / EVAL_HISTORY_FILE, "".join(json.dumps(e) + "\n" for e in history))


def load_run_config(cfg: DictConfig, run_dir: Path) -> tuple[DictConfig, Path, dict | None]:
    """``(config, run dir, checkpoint or None)`` of the run ``cfg`` asks for: a new run in
    ``run_dir``, or with ``resume=<dir>`` that run's checkpointed config (see
    :func:`resume_config`), dir and checkpoint. The config is validated (ConfigError); a new
    run into a dir that holds another run's checkpoint, metrics or evaluation is refused
    (ConfigError naming ``resume=``), before anything is written there."""
    ckpt, auto = None, cfg.resume == RESUME_AUTO
    if auto:  # this job's own dir: continue what an earlier attempt left there (or start it again)
        cfg.resume = str(run_dir) if (Path(run_dir) / CHECKPOINT_FILE).is_file() else None
    if cfg.resume:
        ckpt = load_checkpoint(cfg.resume)
        if Path(cfg.resume).resolve() != Path(run_dir).resolve():
            log.info("resume: continuing %s (this invocation's own dir is %s)", cfg.resume, run_dir)
            run_dir = Path(cfg.resume)
        cfg = resume_config(ckpt["config"], cfg)
    elif not auto and (held := [f for f in (CHECKPOINT_FILE, METRICS_FILE, EVAL_FILE) if (Path(run_dir) / f).exists()]):
        # a new run there would truncate another run's files (even a live one's)
        raise ConfigError(f"{display_path(run_dir)} already holds a training run ({', '.join(held)}): continue it "
                          f"with resume={display_path(run_dir)} (or resume=auto), or give another hydra.run.dir")
    validate(cfg)
    return cfg, Path(run_dir), ckpt


def make_run(cfg: DictConfig, run_dir: Path, ckpt: dict | None = None) -> Run:
    """The parts of a run (``cfg`` validated), fresh or from ``ckpt``; writes config.yaml
    into a new run's dir."""
    set_threads(cfg.threads)
    seed_everything(cfg.seed)
    device = resolve_device(cfg.device)
    run_dir.mkdir(parents=True, exist_ok=True)
    if ckpt is None:
        atomic_write_text(run_dir / CONFIG_FILE, OmegaConf.to_yaml(_plain(cfg)))
    env = make_train_env(cfg, seed=cfg.seed)
    obs_dim = env.observation_spec_unbatched["observation"].shape[-1]
    agent = make_agent(cfg.algo, obs_dim, env.action_spec_unbatched, num_envs=cfg.env.num_envs, device=device)
    if cfg.compile:
        agent.compile()
    stages = make_curriculum(cfg, agent)
    rb = make_replay_buffer(cfg, device) if cfg.algo.name in REPLAY else None
    if ckpt is None:
        state = RunState.fresh(cfg.budget)
    else:
        state = RunState.restore(ckpt, agent, rb, env_rngs(env), device, carrier_spec(env))
        log.info("resumed from %s at %d frames, %d updates", display_path(run_dir), state.frames, agent.n_updates)
    metric_names = agent.metric_names + (("stage",) if stages else ())
    logger = MetricLogger(cfg, run_dir, metric_names, resume_step=None if ckpt is None else state.frames,
                          wandb_id=state.wandb_id)
    state.wandb_id = logger.wandb_id
    if ckpt is not None:  # the history file reads as one run, like metrics.csv
        write_eval_history(run_dir, state.eval_history)
    run = Run(cfg, run_dir, device, env, agent, rb, state, logger, stages, Window(agent.n_updates))
    run.update_stage()
    return run


# ----------------------------------------------------------------------------- the cadence


class StopRequests:
    """SIGINT (Ctrl-C), SIGTERM and SIGUSR1 (a scheduler's preemption notice: SLURM, submitit)
    while a run trains: the handler only records the signal; the loop checks between any two
    gradient updates of a batch (:func:`gradient_updates`: the rest stay owed) and after each batch,
    writes a checkpoint at that step and exits with 128 + the signal's number, so nothing finished
    is lost and ``resume=<run dir>`` continues to the uninterrupted run's result (a batch boundary:
    the checkpoint holds the collector's state there). A second Ctrl-C stops at once
    (KeyboardInterrupt), losing at most what came after the last checkpoint. Installed only in
    the main thread."""

    SIGNALS = ("SIGINT", "SIGTERM", "SIGUSR1")

    def __init__(self):
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    def _handle(self, signum, frame) -> None:
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.signum = signum
        log.warning("%s received: stopping after this batch with a checkpoint (Ctrl-C again stops at once)",
                    signal.Signals(signum).name)

    def __enter__(self) -> "StopRequests":
        import threading

        if threading.current_thread() is threading.main_thread():
            for name in self.SIGNALS:
                if hasattr(signal, name):
                    num = getattr(signal, name)
                    self._previous[num] = signal.signal(num, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for num, handler in self._previous.items():
            signal.signal(num, handler)
        self._previous.clear()

    def stop_if_requested(self, run: "Run") -> None:
        """After a batch: if a signal came, checkpoint at this step and exit 128 + its number."""
        if self.signum is None:
            return
        if run.window.frames:
            run.log_window()
        run.checkpoint()
        name = signal.Signals(self.signum).name
        log.warning("stopped by %s at %d frames: checkpoint written; continue with: python train.py resume=%s",
                    name, run.state.frames, display_path(run.run_dir))
        raise SystemExit(128 + self.signum)


def _next_multiple(frames: int, every: int) -> int:
    return (frames // every + 1) * every


def periodic(run: Run, bar) -> None:
    """What is due after a batch, in this order: a metric row (every budget.log_every frames),
    an evaluation (eval_every) and a checkpoint (checkpoint_every); the last two not once the
    budget is spent, since the final evaluation and checkpoint follow. The steps at which each
    is next due are in the run state, so a resumed run keeps the cadence."""
    state, b = run.state, run.cfg.budget
    if state.frames >= state.next_log:
        run.log_window()
        state.next_log = _next_multiple(state.frames, b.log_every)
    done = run.budget_spent()
    if state.frames >= state.next_eval and not done:
        run.evaluate(b.eval_innings, eval_starts(run.cfg)[0], final=False)
        state.next_eval = _next_multiple(state.frames, b.eval_every)
    if state.frames >= state.next_ckpt and not done:
        state.next_ckpt = _next_multiple(state.frames, b.checkpoint_every)
        run.checkpoint()
    postfix = {"ups": f"{run.window.ups(run.agent.n_updates):.0f}"}
    if state.eval_history:
        postfix["eval"] = f"{state.eval_history[-1]['eval_mean']:.2f}"
    bar.set_postfix(postfix, refresh=False)


@contextmanager
def session(run: Run) -> Iterator[tqdm]:
    """Around a loop: compiles the simulator's kernels, starts the run's clock and shows a
    progress bar; closes the logger at the end."""
    cfg, b = run.cfg, run.cfg.budget
    params = params_from_config(cfg.physics)
    log.info("output: %s (%s, %s steps, physics %s) on %s", display_path(run.run_dir), cfg.algo.name, f"{b.total_steps:,}",
             params.describe(), run.device)
    warm_up(params, log=log.info)
    run.state.start_clock()
    interactive = sys.stderr.isatty()
    with tqdm(total=b.total_steps, initial=run.state.frames, unit="shot", unit_scale=True, dynamic_ncols=True,
              mininterval=1.0 if interactive else 30.0, disable=not cfg.progress, file=sys.stderr,
              desc=f"{cfg.algo.name} {run.run_dir.name}", smoothing=0.05) as bar:
        yield bar
    run.logger.close()
    log.info("done: %s, summary.json and checkpoint.pt in %s", EVAL_FILE, display_path(run.run_dir))


def finish(run: Run, bar) -> float:
    """The final evaluation from every start (eval.json, eval_<start>.json), summary.json and
    the last checkpoint; returns the primary start's mean points per inning."""
    cfg, state, agent = run.cfg, run.state, run.agent
    if run.window.frames:
        run.log_window()
    results, lives = [], {}
    for i, start in enumerate(eval_starts(cfg)):
        result, live = run.evaluate(cfg.budget.final_eval_innings, start, final=True)
        results.append(result)
        if live is not None:
            lives[start] = eval_row(live)
        result.to_json(run.run_dir / (EVAL_FILE if i == 0 else f"eval_{start}.json"))
    train_seconds, cpu_seconds = state.times()
    summary = {
        "algo": cfg.algo.name,
        "table": cfg.table,
        "seed": cfg.seed,
        "frames": state.frames,
        "updates": agent.n_updates,
        **physics_record(params_from_config(cfg.physics)),
        **noise_record(noise_from_config(cfg.noise)),
        "device": str(run.device),
        "stopped_by": "total_steps" if state.frames >= cfg.budget.total_steps else "cpu_minutes",
        "train_seconds": round(train_seconds, 2),
        "cpu_seconds": round(cpu_seconds, 2),
        "frames_per_second": round(state.frames / max(train_seconds, 1e-9), 1),
        "updates_per_second": round(agent.n_updates / max(train_seconds, 1e-9), 2),
        "eval": {r.start: eval_row(r) for r in results},
    }
    if lives:  # eval is the averaged actor's (algo.actor_ema); this, the live actor's
        summary["eval_live"] = lives
    if run.stages is not None:
        summary["curriculum"] = state.stage_log
    atomic_write_text(run.run_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    for r in results:
        log.info("final eval (%s start): %s", r.start, r.summary())
    bar.set_postfix(eval=f"{results[0].mean:.2f}")  # the final evaluation, not the last periodic one
    run.checkpoint()
    return results[0].mean


# ----------------------------------------------------------------------------- the loops


@contextmanager
def collecting(run: Run, policy, frames_per_batch: int) -> Iterator[Iterable[TensorDictBase]]:
    """The batches of a :func:`make_collector` until the budget's frames are collected (none
    if the budget is already spent); the collector is shut down at the end. A resumed run's
    collector first gets the checkpoint's collector and random states back
    (:meth:`RunState.resume_collector`), and ``run.collector`` is the collector meanwhile, so
    that every checkpoint written between two batches holds its state."""
    if run.budget_spent():
        yield ()
        return
    collector = make_collector(run, policy, frames_per_batch)
    run.state.resume_collector(collector, env_rngs(run.env), run.device)
    run.collector = collector
    try:
        yield collector
    finally:
        run.collector = None
        collector.shutdown()


def gradient_updates(run: Run, stop: StopRequests, count: int) -> bool:
    """``count`` gradient updates (off-policy: utd x a batch's frames), each on a fresh sample of
    the replay buffer, a stop request (a signal) seen between any two of them: the updates not
    made stay owed (the run state's ``owed``, checkpointed), and the resumed run makes them
    before its next batch, as the uninterrupted run did. Whether all ``count`` were made."""
    for i in range(count):
        if stop.signum is not None:
            run.state.owed += count - i
            return False
        run.window.metrics = run.agent.update(run.rb.sample())
    return True


def after_updates(run: Run, bar, stop: StopRequests, complete: bool, frames: int) -> bool:
    """After a batch of ``frames`` frames and its gradient updates (``complete``: all made):
    the warm-up flag, the curriculum's stage, the progress bar and what is due
    (:func:`periodic`), then a stop request (a checkpoint and exit; updates left owed are made
    by the resumed run first, before these). Whether the CPU budget is spent."""
    if complete:
        run.agent.set_warmup(run.state.frames < run.cfg.budget.init_random_steps)
        run.update_stage()
        bar.update(frames)
        periodic(run, bar)
    stop.stop_if_requested(run)
    return run.cpu_spent()


def train_off_policy(run: Run) -> float:
    """SAC and TD3 to the budget; returns the final mean points per inning."""
    cfg, agent, rb, state = run.cfg, run.agent, run.rb, run.state
    a, b = cfg.algo, cfg.budget
    with session(run) as bar, StopRequests() as stop:
        agent.set_warmup(state.frames < b.init_random_steps)
        with collecting(run, agent.explore, a.frames_per_batch or cfg.env.num_envs) as batches:
            spent = False
            if state.owed >= 1:  # stopped amid a batch's updates: the rest first, as the uninterrupted run made them
                spent = after_updates(run, bar, stop, gradient_updates(run, stop, state.take_updates(0.0)), 0)
            for data in () if spent else batches:
                n = data.numel()
                state.frames += n
                rb.extend(data.reshape(-1).select(*agent.replay_keys))
                run.window.add(data)
                count = state.take_updates(a.utd * n) if state.frames >= b.init_random_steps else 0
                if after_updates(run, bar, stop, gradient_updates(run, stop, count), n):
                    break
        return finish(run, bar)


def train_ppo(run: Run) -> float:
    """PPO to the budget; returns the final mean points per inning."""
    cfg, agent, state = run.cfg, run.agent, run.state
    a = cfg.algo
    with session(run) as bar, StopRequests() as stop:
        with collecting(run, agent.explore, a.frames_per_batch) as batches:
            for data in batches:
                n = data.numel()
                state.frames += n
                run.window.add(data)
                for _ in range(a.epochs):
                    flat = agent.advantage(data).reshape(-1)
                    perm = torch.randperm(n).to(flat.device)  # torch's CPU generator on every device
                    for i in range(0, n - a.minibatch_size + 1, a.minibatch_size):
                        run.window.metrics = agent.update(flat[perm[i:i + a.minibatch_size]])
                bar.update(n)
                periodic(run, bar)
                stop.stop_if_requested(run)
                if run.cpu_spent():
                    break
        return finish(run, bar)


def train(cfg: DictConfig, run_dir: str | Path | None = None, loops: dict | None = None) -> float:
    """Train as configured; returns the final mean points per inning (primary eval start).

    ``run_dir`` defaults to Hydra's output dir of the job (or the resumed run's dir).
    Resuming a finished run builds and writes nothing: it says so and returns its result.
    ``loops``: training loops by algorithm name, each given the built :class:`Run`, beside the
    ones here (SAC, TD3, PPO): ``algo=exit``'s lives above this layer
    (:func:`billiards.exit.train_exit`; train.py passes it).
    """
    if run_dir is None:
        from hydra.core.hydra_config import HydraConfig

        run_dir = HydraConfig.get().runtime.output_dir
    try:
        cfg, run_dir, ckpt = load_run_config(cfg, Path(run_dir))
        finished = finished_result(ckpt, cfg, run_dir) if ckpt is not None else None
        if finished is not None:
            mean, frames = finished
            log.warning(finished_line(run_dir, frames, mean))
            return mean
        loop = {**LOOPS, **(loops or {})}.get(cfg.algo.name)
        if loop is None:
            raise ConfigError(f"algo={cfg.algo.name} has no training loop here: train it with train.py")
    except (CheckpointError, ConfigError) as err:
        raise SystemExit(f"Error: {err}") from None
    held = ExitStack()
    try:  # one writer per run folder: a second run started on it meanwhile is refused at once, naming this one
        held.enter_context(run_lock(run_dir, say=log.warning))
    except RunLockedError as err:
        raise SystemExit(f"Error: {err}") from None
    with held:
        try:
            run = make_run(cfg, run_dir, ckpt)
            record_start(run_dir, "fresh" if ckpt is None else "resume", run.state.frames,
                         command=["python", "train.py", *_command_line_overrides()])
        except (CheckpointError, ConfigError) as err:
            raise SystemExit(f"Error: {err}") from None
        return loop(run)


# algo.name -> its loop (algo=exit's is billiards.exit.train_exit, passed by train.py)
LOOPS = {**{name: train_off_policy for name in OFF_POLICY}, "ppo": train_ppo}
