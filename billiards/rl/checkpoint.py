"""Checkpoints of a training run: one file, ``<run dir>/checkpoint.pt``, replaced atomically,
and :class:`RunState`, everything a resume needs, captured into it and restored from it here
and nowhere else.

Contents (a dict of tensors and plain Python types only: dict, list, tuple, str, int, float,
bool, None, so that it loads with ``torch.load(..., weights_only=True)`` and loading never
runs code from the file):

* ``config``: the resolved training config (plain containers);
* ``agent``: the agent's ``state_dict`` (actor, critics, target critics / target actor,
  SAC's log-temperature, the averaged actor) and ``agent_extra`` (optimizer states, update
  counter);
* ``buffer``: the filled part of the replay buffer as a nested dict of tensors, its row
  count and its write cursor (off-policy, unless ``checkpoint.save_buffer=false``), or None;
* ``counters``: env frames, fractional update debt, next log/eval/checkpoint steps,
  accumulated training seconds (wall-clock and CPU);
* ``eval_history``: every evaluation so far;
* ``rng``: torch, numpy, python and the training env's rack and execution-noise generator
  states (:func:`rng_state`: numpy arrays as lists of ints), and the CUDA generator's of a run
  on a GPU;
* ``collector``: what the collector holds between two batches (:func:`collector_state`): the
  tensordict the next env step starts from (every inning's table, shot count and done flags)
  and the next trajectory id; None when no collector was running (the final checkpoint);
* ``wandb_id``: to continue the same wandb run;
* ``stage_log``: the curriculum stages entered so far;
* ``format_version`` (2) and ``schema``, the version of this content
  (:data:`billiards.compat.CHECKPOINT`: :func:`load_checkpoint` reads a checkpoint of an
  earlier content through :func:`billiards.compat.upgrade_checkpoint`).

Tensors are saved as they are and loaded onto the CPU (``map_location``); restoring copies
them onto the run's device, so a run can resume on another device than it started on.

File layout (format 2)::

    billiards-checkpoint 2\\n
    sha256 <64 hex digits>\\n
    <torch.save of the dict above>

The digest is the SHA-256 of the first line and the payload, so a changed byte anywhere in the
file (header, digest or payload) is detected on load and the file refused instead of resumed
on damaged weights. Written with :func:`billiards.files.atomic_open` (temporary file, fsync,
``os.replace``), so a kill at any moment leaves either the previous or the new checkpoint.
A file of another format is refused (:func:`billiards.compat.checkpoint_format_refusal` names
the one before this).
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import logging
import math
import os
import pickle
import random
import re
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from billiards import compat
from billiards.files import RunFileError, atomic_open, key_problem, open_run_file, plain_data_problem, shape_problem, tensor_problem

from .config import ALGO_SCHEMAS, CHECKPOINT_FILE, MAX_LAYERS, MAX_WIDTH, REPLAY

FORMAT_VERSION = 2
MAGIC = b"billiards-checkpoint"
_HEADER = re.compile(rb"(billiards-checkpoint (\d{1,6})\n)sha256 ([0-9a-f]{64})\n")
_HEADER_MAX = 128  # bytes: the header is about 94
_PLAIN = (str, int, float, bool, type(None), bytes, torch.Tensor)
REQUIRED = ("config", "agent", "agent_extra", "buffer", "counters", "eval_history", "rng", "collector", "wandb_id",
            "stage_log")

log = logging.getLogger(__name__)


class CheckpointError(RuntimeError):
    """A missing, unreadable or incompatible checkpoint; the message says what to do."""


# ----------------------------------------------------------------------------- rng states


def _plain_array(value: Any) -> Any:
    """A numpy bit-generator state with its arrays as lists of ints (plain, loadable safely)."""
    if isinstance(value, dict):
        return {k: _plain_array(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


EnvRngs = np.random.Generator | Mapping[str, np.random.Generator]


def _env_rngs(env_rngs: EnvRngs) -> Mapping[str, np.random.Generator]:
    return {"env": env_rngs} if isinstance(env_rngs, np.random.Generator) else env_rngs


def rng_state(env_rngs: EnvRngs, device: torch.device | None = None) -> dict[str, Any]:
    """Every random state a training run draws from, as tensors and plain types: torch's,
    numpy's global one, Python's ``random``, the training env's generators and, on a CUDA
    ``device``, that GPU's generator. ``env_rngs``: the env's generators by name (the trainer
    passes ``{"env": racks, "env_noise": execution noise}``), or one Generator, the racks'."""
    version, internal, gauss_next = random.getstate()
    state = {
        "torch": torch.get_rng_state(),
        "numpy": _plain_array(np.random.get_state(legacy=False)),
        "python": {"version": version, "internal": list(internal), "gauss_next": gauss_next},
    }
    state |= {name: _plain_array(rng.bit_generator.state) for name, rng in _env_rngs(env_rngs).items()}
    if device is not None and torch.device(device).type == "cuda":
        state["cuda"] = torch.cuda.get_rng_state(device)
    return state


def set_rng_state(state: dict[str, Any], env_rngs: EnvRngs, device: torch.device | None = None) -> None:
    """Restore what :func:`rng_state` saved (numpy accepts its states with lists for arrays):
    every generator of ``env_rngs`` must be in ``state``; one whose entry is None is left as it
    is (its state was not saved: :data:`billiards.compat.CHECKPOINT`). A saved CUDA generator
    state goes to a CUDA ``device`` (a CPU run has none to restore)."""
    torch.set_rng_state(state["torch"])
    np.random.set_state(state["numpy"])
    py = state["python"]
    random.setstate((py["version"], tuple(py["internal"]), py["gauss_next"]))
    for name, rng in _env_rngs(env_rngs).items():
        if state[name] is not None:
            rng.bit_generator.state = state[name]
    if "cuda" in state and device is not None and torch.device(device).type == "cuda":
        torch.cuda.set_rng_state(state["cuda"], device)


# ----------------------------------------------------------------------------- the collector


def collector_state(collector) -> dict[str, Any] | None:
    """What a TorchRL 0.14 :class:`~torchrl.collectors.Collector` holds between two batches and
    a resume needs to collect the very batches the uninterrupted run would: its carrier, the
    tensordict the next env step starts from (every inning's table, shot count, observation
    and done flags; a nested dict of CPU tensors), and the next trajectory id. None if the
    collector holds none (it was shut down)."""
    carrier = getattr(collector, "_carrier", None)
    if carrier is None:
        return None
    state: dict[str, Any] = {"carrier": carrier.detach().to("cpu").clone().to_dict()}
    if getattr(collector, "track_traj_ids", False):
        state["traj_id"] = int(collector._traj_pool.state_dict()["traj_id"])
    return state


def _collector_from(entry: Any, carrier_spec) -> dict[str, Any]:
    """The checkpoint's collector entry with its carrier as a TensorDict of the env's batch,
    checked against ``carrier_spec`` (the env's observation and done specs: every key there,
    of its shape and dtype, within its bounds), or CheckpointError."""
    from tensordict import TensorDict

    try:
        carrier = TensorDict(entry["carrier"], batch_size=carrier_spec.shape)
        traj_id = entry.get("traj_id")
        if traj_id is not None and (isinstance(traj_id, bool) or not isinstance(traj_id, int) or traj_id < 0):
            raise ValueError(f"traj_id={traj_id!r}")
    except (KeyError, TypeError, ValueError, RuntimeError, AttributeError) as err:
        raise CheckpointError(f"cannot resume: the checkpoint's collector state is malformed ({type(err).__name__}: "
                              f"{err}); it is corrupt, start a new run") from None
    bad = [str(key) for key, spec in carrier_spec.items(True, True)
           if not isinstance(carrier.get(key, None), torch.Tensor) or not spec.is_in(carrier.get(key))]
    if bad:
        raise CheckpointError(f"cannot resume: the checkpoint's collector state does not fit this env ({', '.join(bad)}); "
                              f"it is corrupt, start a new run")
    return {"carrier": carrier, "traj_id": traj_id}


# ----------------------------------------------------------------------------- the run state


@dataclass
class RunState:
    """Everything of a training run that is not its config and that a resume needs, with
    :meth:`capture` (into the checkpoint dict) and :meth:`restore` (out of it) side by side.

    Plain fields are the run's counters; the agent (networks, optimizers), the replay buffer
    and the random generators are captured from and restored into the objects the run is
    made of. ``next_*`` are the frame counts at which the next metric row, periodic evaluation
    and checkpoint are due (``inf``: never). ``train_seconds`` and ``cpu_seconds`` are the
    wall-clock and process CPU seconds of the run's earlier processes; :meth:`times` adds this
    process's since :meth:`start_clock`.

    A restored state also keeps the checkpoint's collector state and random states (``pending``)
    until :meth:`resume_collector` puts them into the run's new collector, right before its
    first batch: building a collector resets the env (drawing racks) and may run the policy,
    so the generators are set again after that, and the resumed run collects, draws and updates
    exactly as the uninterrupted run did after the checkpoint.
    """

    frames: int = 0
    owed: float = 0.0  # fractional gradient updates carried over (off-policy)
    train_seconds: float = 0.0
    cpu_seconds: float = 0.0
    next_log: float = 0
    next_eval: float = math.inf
    next_ckpt: float = math.inf
    eval_history: list[dict] = field(default_factory=list)
    stage_log: list[dict] = field(default_factory=list)  # {"stage", "from_step", "free", "step"} at each stage entry
    wandb_id: str | None = None
    pending: dict[str, Any] | None = field(default=None, repr=False)  # {"collector", "rng"} until resume_collector
    _t0: float = field(default=0.0, repr=False)
    _c0: float = field(default=0.0, repr=False)

    @classmethod
    def fresh(cls, budget) -> RunState:
        """The state of a run that has not started (``budget``: the config's budget node)."""
        return cls(next_log=budget.log_every, next_eval=budget.eval_every or math.inf,
                   next_ckpt=budget.checkpoint_every or math.inf)

    def start_clock(self) -> None:
        self._t0, self._c0 = time.perf_counter(), time.process_time()

    def times(self) -> tuple[float, float]:
        """Training wall-clock and CPU seconds so far, over all processes of this run."""
        return (self.train_seconds + time.perf_counter() - self._t0,
                self.cpu_seconds + time.process_time() - self._c0)

    def take_updates(self, amount: float) -> int:
        """Whole gradient updates owed after adding ``amount`` (utd x frames); the fraction
        is carried over to the next batch."""
        self.owed += amount
        k = int(self.owed)
        self.owed -= k
        return k

    def capture(self, config: dict, agent, rb, env_rngs: EnvRngs, *, collector=None, save_buffer: bool = True,
                device: torch.device | None = None) -> dict[str, Any]:
        """The checkpoint dict (see the module docstring) of this state, ``config`` (plain),
        the agent, the replay buffer ``rb`` (None for PPO; left out unless ``save_buffer``),
        the running ``collector``'s state (None: none running) and every random generator."""
        buffer = None
        if rb is not None and save_buffer and len(rb):
            n = len(rb)  # a TensorDict is no plain type: its nested dict of tensors and its length
            rows = rb.storage[:n]
            rows = rows.clone() if rows.device in (None, torch.device("cpu")) else rows.to("cpu")  # a compact CPU copy
            buffer = {"data": rows.to_dict(), "rows": n, "writer": rb.writer.state_dict()}
        train_seconds, cpu_seconds = self.times()
        return {
            "config": config,
            "agent": agent.state_dict(),
            "agent_extra": agent.state_dict_extra(),
            "buffer": buffer,
            "counters": {
                "frames": self.frames,
                "owed": self.owed,
                "train_seconds": train_seconds,
                "cpu_seconds": cpu_seconds,
                "next_log": self.next_log,
                "next_eval": self.next_eval,
                "next_ckpt": self.next_ckpt,
            },
            "eval_history": self.eval_history,
            "rng": rng_state(env_rngs, device),
            "collector": None if collector is None else collector_state(collector),
            "wandb_id": self.wandb_id,
            "stage_log": self.stage_log,
        }

    @classmethod
    def restore(cls, ckpt: dict[str, Any], agent, rb, env_rngs: EnvRngs, device: torch.device | None = None,
                carrier_spec=None) -> RunState:
        """Puts a checkpoint's networks, optimizers, replay buffer and random generators back
        into the run's objects and returns its counters, with its collector state (checked
        against ``carrier_spec``, the env's observation and done specs) pending for
        :meth:`resume_collector`. ``ckpt``: a checkpoint of today's form (:func:`load_checkpoint`
        reads every earlier one through :func:`billiards.compat.upgrade_checkpoint`)."""
        _LAST.clear()  # the run holds what it needs now
        try:
            agent.load_state_dict(ckpt["agent"])
            agent.load_state_dict_extra(ckpt["agent_extra"])
        except (RuntimeError, KeyError, ValueError) as err:
            raise CheckpointError(f"cannot resume: the checkpoint's networks do not fit this config ({err})") from None
        c = check_counters(ckpt)
        state = cls(frames=int(c["frames"]), owed=float(c["owed"]), train_seconds=float(c["train_seconds"]),
                    cpu_seconds=float(c["cpu_seconds"]), next_log=c["next_log"], next_eval=c["next_eval"],
                    next_ckpt=c["next_ckpt"], eval_history=list(ckpt["eval_history"]),
                    stage_log=list(ckpt["stage_log"]), wandb_id=ckpt["wandb_id"])
        buffer = ckpt["buffer"]
        if rb is not None and buffer is not None:
            from tensordict import TensorDict

            rb.extend(TensorDict(buffer["data"], batch_size=[buffer["rows"]]))
            rb.writer.load_state_dict(buffer["writer"])
        elif rb is not None:
            log.warning("resume: the checkpoint has no replay buffer (checkpoint.save_buffer=false); refilling from scratch")
        try:
            set_rng_state(ckpt["rng"], env_rngs, device)
        except (TypeError, ValueError, KeyError, IndexError, RuntimeError, OverflowError) as err:
            raise CheckpointError(f"cannot resume: the checkpoint's random-generator state is malformed "
                                  f"({type(err).__name__}: {err}); it is corrupt, start a new run") from None
        entry = ckpt["collector"]
        if entry is not None and carrier_spec is not None:
            state.pending = {"collector": _collector_from(entry, carrier_spec), "rng": ckpt["rng"]}
        elif carrier_spec is not None:
            log.info("resume: the checkpoint holds no collector state (it was written when no collector was running): "
                     "the innings in progress are not restored, the collector starts fresh ones")
        return state

    def resume_collector(self, collector, env_rngs: EnvRngs, device: torch.device | None = None) -> None:
        """Into a collector just built for the resumed run: the checkpoint's carrier and next
        trajectory id, then every random generator's state at the checkpoint again (no-op
        unless :meth:`restore` left them pending)."""
        if self.pending is None:
            return
        pending, self.pending = self.pending, None
        saved = pending["collector"]
        collector._carrier.update(saved["carrier"])
        if saved["traj_id"] is not None and getattr(collector, "track_traj_ids", False):
            collector._traj_pool.load_state_dict({"traj_id": torch.tensor(saved["traj_id"], dtype=torch.int)})
        set_rng_state(pending["rng"], env_rngs, device)


def _most_owed(config: Any) -> float:
    """The most gradient updates a checkpoint may owe: what its algorithm's schema says a run
    stopped amid its updates may owe (:meth:`~billiards.rl.config.AlgoConfig.most_owed`: one
    collector batch's off-policy, one round's for expert iteration), plus the fraction carried over."""
    try:
        algo, env = config["algo"], config["env"]
        schema = ALGO_SCHEMAS.get(algo.get("name"))
        return (0.0 if schema is None else schema.most_owed(algo, env)) + 1.0
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError):
        return 1.0


def check_counters(ckpt: dict[str, Any], what: str = "the checkpoint") -> dict[str, Any]:
    """The checkpoint's counters, or a CheckpointError if one is impossible: frames an integer in
    [0, budget.total_steps + 10^6] (the run's own budget, and a batch's overshoot), times and owed
    updates finite and >= 0, the next log / evaluation / checkpoint steps numbers >= 0 (inf: never),
    the histories lists. A checksum proves a file is what was written, not that it made sense."""
    c = ckpt.get("counters")
    if not isinstance(c, dict):
        raise CheckpointError(f"cannot resume: {what}'s counters are not a mapping; it is corrupt, start a new run")
    try:
        total = int(ckpt["config"]["budget"]["total_steps"])
    except (KeyError, TypeError, ValueError):
        total = 0
    bad = []
    frames = c.get("frames")
    if isinstance(frames, bool) or not isinstance(frames, int) or not 0 <= frames <= total + 10**6:
        bad.append(f"frames={frames!r} (an integer in [0, {total + 10**6:,}])")
    for key in ("owed", "train_seconds", "cpu_seconds"):
        v = c.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v >= 0):
            bad.append(f"{key}={v!r} (a finite number >= 0)")
    owed = c.get("owed")
    if isinstance(owed, (int, float)) and not isinstance(owed, bool) and owed > (most := _most_owed(ckpt.get("config"))):
        bad.append(f"owed={owed!r} (the gradient updates of at most one batch: {most:,.0f})")
    for key in ("next_log", "next_eval", "next_ckpt"):
        v = c.get(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or v < 0:
            bad.append(f"{key}={v!r} (a step >= 0 or inf)")
    for key in ("eval_history", "stage_log"):
        if not isinstance(ckpt.get(key), list):
            bad.append(f"{key} (a list)")
    if bad:
        raise CheckpointError(f"cannot resume: {what} holds impossible counters: {', '.join(bad)}; "
                              f"it is corrupt, start a new run")
    return c


# ----------------------------------------------------------------------------- the content


def config_problem(config: Any, where: str = "config") -> str | None:
    """What keeps a stored training config (a checkpoint's, an exported policy's) from describing
    networks, or None: not plain data (an interpolation, an object), no algorithm of this
    version, hidden sizes other than 1 to :data:`MAX_LAYERS` widths in [1, :data:`MAX_WIDTH`],
    env flags that are not booleans, no noise node or one its schema refuses."""
    from billiards.physics.noise import noise_errors

    if (bad := plain_data_problem(config, where)) or (bad := key_problem(config, {"algo": dict, "env": dict}, where)):
        return bad
    algo, env = config["algo"], config["env"]
    if algo.get("name") not in ALGO_SCHEMAS:
        return f"{where}.algo.name={algo.get('name')!r}: not an algorithm of this version ({', '.join(ALGO_SCHEMAS)})"
    hidden = algo.get("hidden_sizes")
    if not (isinstance(hidden, list) and 0 < len(hidden) <= MAX_LAYERS
            and all(isinstance(h, int) and not isinstance(h, bool) and 1 <= h <= MAX_WIDTH for h in hidden)):
        return f"{where}.algo.hidden_sizes={hidden!r}: not 1 to {MAX_LAYERS} layer widths in [1, {MAX_WIDTH}]"
    for key in ("constrain_aim", "extra_features"):
        if not isinstance(env.get(key, False), bool):
            return f"{where}.env.{key}={env.get(key)!r}: not a boolean"
    if bad := key_problem(config, {"noise": dict}, where) or key_problem(config["noise"], {"preset": str}, f"{where}.noise"):
        return bad
    if errs := noise_errors(config["noise"]):
        return f"{where}.noise: {errs[0]}"
    return None


def agent_from_config(config: dict):
    """``(agent, cfg)``: the agent (networks and optimisers, on the CPU, freshly initialised) a
    stored training config describes, and the config as a DictConfig: what a checkpoint's or an
    exported policy's tensors must fit. Only the observation and action layout matter (no
    shaping: no reward model is loaded); variable noise adds the level to the observation. The
    algorithm's node is merged into its schema (a key the stored config leaves out takes the
    schema's default: :mod:`billiards.compat`). ``config``: in today's form (the loaders read it
    through :mod:`billiards.compat`); check it with :func:`config_problem` first; a config that
    still does not build a network raises :class:`CheckpointError`."""
    from omegaconf import OmegaConf

    from billiards.envs import make_env
    from billiards.physics.noise import noise_from_config

    from .learners import make_agent

    cfg = OmegaConf.create(config)
    try:
        schema = ALGO_SCHEMAS[cfg.algo.name]
        own = {f.name for f in dataclasses.fields(schema)}
        algo = OmegaConf.merge(OmegaConf.structured(schema), {k: v for k, v in config["algo"].items() if k in own})
        env = make_env(1, constrain_aim=bool(cfg.env.get("constrain_aim", False)),
                       extra_features=bool(cfg.env.get("extra_features", False)), noise=noise_from_config(cfg.noise))
        obs_dim = env.observation_spec_unbatched["observation"].shape[-1]
        return make_agent(algo, obs_dim, env.action_spec_unbatched), cfg
    except Exception as err:  # a config that passed config_problem and still builds nothing: say so, no traceback
        raise CheckpointError(f"its config does not describe networks ({type(err).__name__}: "
                              f"{str(err).splitlines()[0] if str(err) else ''})") from None


def _optimizer_problem(agent, extra: Any) -> str | None:
    """What is wrong with ``extra`` (a checkpoint's ``agent_extra``) against ``agent`` (built from
    its config): an optimiser missing or of another network (its groups, its state's indices),
    a state tensor whose shape is not its parameter's, a non-finite or complex value, an update
    counter that is not an integer >= 0."""
    built = agent.state_dict_extra()
    spec = {key: (int if key == "n_updates" else dict) for key in built}
    if bad := key_problem(extra, spec, "agent_extra"):
        return bad
    if extra["n_updates"] < 0:
        return f"agent_extra.n_updates={extra['n_updates']}: not a count"
    for key, own in built.items():
        if key == "n_updates":
            continue
        where, saved = f"agent_extra.{key}", extra[key]
        if bad := key_problem(saved, {"state": dict, "param_groups": list}, where):
            return bad
        groups = saved["param_groups"]
        if len(groups) != len(own["param_groups"]) or any(
                not isinstance(g, dict) or list(g.get("params", ())) != list(o["params"])
                for g, o in zip(groups, own["param_groups"])):
            return f"{where}.param_groups: not the optimiser of the networks its config describes"
        for g in groups:
            for name, v in g.items():
                numbers = v if isinstance(v, (list, tuple)) else [v]
                if name != "params" and any(isinstance(x, float) and not math.isfinite(x) for x in numbers):
                    return f"{where}.param_groups: {name}={v!r} is not finite"
        params = [p for g in getattr(agent, key).param_groups for p in g["params"]]
        for idx, st in saved["state"].items():
            if isinstance(idx, bool) or not isinstance(idx, int) or not 0 <= idx < len(params) or not isinstance(st, dict):
                return f"{where}.state: entry {idx!r} is not the state of one of its {len(params)} parameters"
            for name, v in st.items():
                if name == "step":
                    continue
                if not torch.is_tensor(v) or tuple(v.shape) != tuple(params[idx].shape):
                    shape = tuple(v.shape) if torch.is_tensor(v) else type(v).__name__
                    return (f"{where}.state.{idx}.{name}: shape {shape}, but the parameter it belongs to has "
                            f"{tuple(params[idx].shape)}")
        if bad := tensor_problem(saved["state"], f"{where}.state", floats_only=False):
            return bad
    return None


def _leading_sizes(tree: Any, name: str):
    """(name, first dimension) of every tensor in a nested dict."""
    if torch.is_tensor(tree):
        yield name, (tree.shape[0] if tree.dim() else None)
    elif isinstance(tree, dict):
        for k, v in tree.items():
            yield from _leading_sizes(v, f"{name}.{k}")


def _buffer_problem(buffer: Any, agent, cfg, frames: int) -> str | None:
    """What is wrong with a checkpoint's replay buffer: kept by an algorithm that has none, its
    row count outside [1, its capacity and the frames collected], a tensor of another row count,
    a replay key missing, a non-finite or complex value, a write cursor outside the buffer."""
    if cfg.algo.name not in REPLAY:
        return f"buffer: a replay buffer, but algo={cfg.algo.name} keeps none"
    if bad := key_problem(buffer, {"data": dict, "rows": int, "writer": dict}, "buffer"):
        return bad
    rows, size, total = buffer["rows"], cfg.algo.get("buffer_size"), cfg.budget.get("total_steps")
    if not all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in (size, total)):
        return f"buffer: its capacity is unknown (config.algo.buffer_size={size!r}, config.budget.total_steps={total!r})"
    capacity = min(size, total)
    if not 1 <= rows <= min(capacity, frames):
        return (f"buffer.rows={rows}: not within [1, {min(capacity, frames):,}] (the buffer's capacity, "
                f"min(algo.buffer_size, budget.total_steps) = {capacity:,}, and the {frames:,} frames collected)")
    if bad := next((f"{n}: {size} rows, the buffer holds {rows}" for n, size in _leading_sizes(buffer["data"], "buffer.data")
                    if size != rows), None):
        return bad
    for key in agent.replay_keys:
        node = buffer["data"]
        for part in (key if isinstance(key, tuple) else (key,)):
            node = node.get(part) if isinstance(node, dict) else None
        if not torch.is_tensor(node):
            return f"buffer.data: lacks {'.'.join(key) if isinstance(key, tuple) else key}, which every replayed frame holds"
    if bad := tensor_problem(buffer["data"], "buffer.data", floats_only=False):
        return bad
    writer = buffer["writer"]
    if any(isinstance(v, bool) or not isinstance(v, int) or v < 0 for v in writer.values()) \
            or not 0 <= writer.get("_cursor", 0) < capacity:
        return f"buffer.writer={writer!r}: not a write cursor within the buffer's {capacity:,} rows"
    return None


def _history_problem(ckpt: dict[str, Any], frames: int) -> str | None:
    """What is wrong with the evaluation history and the curriculum's stage log: not lists of
    records, an evaluation without its step (an integer within the frames collected), its
    ``final`` flag (a boolean) or its mean (a finite number), a stage without its index."""
    for key, spec in (("eval_history", {"step": int, "final": bool, "eval_mean": (int, float)}),
                      ("stage_log", {"stage": int, "step": int})):
        entries = ckpt[key]
        if bad := plain_data_problem(entries, key):
            return bad
        for i, entry in enumerate(entries):
            if bad := key_problem(entry, spec, f"{key}[{i}]"):
                return bad
            if not 0 <= entry["step"] <= frames:
                return f"{key}[{i}].step={entry['step']}: not within the {frames:,} frames collected"
            if key == "eval_history" and not math.isfinite(entry["eval_mean"]):
                return f"{key}[{i}].eval_mean={entry['eval_mean']!r}: not a finite number"
    return None


def check_checkpoint(state: dict[str, Any], path) -> None:
    """The one place a training checkpoint's content is checked, after its checksum
    (:func:`load_checkpoint` calls it): its config plain data describing networks
    (:func:`config_problem`); its counters possible (:func:`check_counters`); the agent's
    tensors those of the networks its config builds (names and shapes: another algorithm, other
    layer sizes or observations are refused before anything is loaded), finite and real; the
    optimisers' state of those networks; the replay buffer within its capacity, finite, every
    replay key there; the evaluation history and stage log well-formed. CheckpointError naming
    the file and what is wrong. (The random-generator and collector states are checked where
    they are restored, against the env.)"""

    def bad(why: str) -> CheckpointError:
        return CheckpointError(f"cannot resume: {path} holds an impossible checkpoint: {why}; it is corrupt, start a new run")

    if why := (key_problem(state, {"config": dict, "agent": dict, "agent_extra": dict, "counters": dict, "rng": dict})
               or config_problem(state["config"])):
        raise bad(why)
    if not isinstance(state["config"].get("budget"), dict):
        raise bad("config.budget is missing")
    frames = check_counters(state, str(path))["frames"]
    try:
        agent, cfg = agent_from_config(state["config"])
    except CheckpointError as err:
        raise bad(str(err)) from None
    expected = {k: v.shape for k, v in agent.state_dict().items()}
    why = (tensor_problem(state["agent"], "agent", floats_only=False) or shape_problem(expected, state["agent"], "agent")
           or _optimizer_problem(agent, state["agent_extra"]))
    if why:
        raise bad(f"{why} (its config: algo={cfg.algo.name}, hidden_sizes={list(cfg.algo.hidden_sizes)})")
    if state.get("buffer") is not None and (why := _buffer_problem(state["buffer"], agent, cfg, frames)):
        raise bad(why)
    if why := _history_problem(state, frames):
        raise bad(why)
    if not isinstance(state.get("wandb_id"), (str, type(None))):
        raise bad(f"wandb_id is a {type(state['wandb_id']).__name__}, not a run id")


# ----------------------------------------------------------------------------- the file


def _check_plain(value: Any, where: str) -> None:
    """Raise TypeError naming the entry unless ``value`` is tensors and plain types only."""
    if isinstance(value, dict):
        for k, v in value.items():
            if not isinstance(k, (str, int)):
                raise TypeError(f"{where} has a key of type {type(k).__name__}; checkpoints store str/int keys only")
            _check_plain(v, f"{where}[{k!r}]")
    elif isinstance(value, (list, tuple)):
        for i, v in enumerate(value):
            _check_plain(v, f"{where}[{i}]")
    elif not isinstance(value, _PLAIN):
        raise TypeError(f"{where} is a {type(value).__module__}.{type(value).__name__}; "
                        f"checkpoints store tensors and plain Python types only")


def save_checkpoint(run_dir: Path, state: dict[str, Any]) -> Path:
    """Write ``state`` (tensors and plain types only, else TypeError naming the entry) as
    ``run_dir/checkpoint.pt`` in format 2, content version :data:`billiards.compat.CHECKPOINT`'s
    (see the module docstring); returns the path."""
    state = {"format_version": FORMAT_VERSION, compat.SCHEMA_KEY: compat.CHECKPOINT.version, **state}
    _check_plain(state, "checkpoint")
    buf = io.BytesIO()
    torch.save(state, buf)
    payload = buf.getbuffer()
    first = MAGIC + b" %d\n" % FORMAT_VERSION
    digest = hashlib.sha256(first)
    digest.update(payload)
    path = Path(run_dir) / CHECKPOINT_FILE
    with atomic_open(path, "wb") as f:
        f.write(first + b"sha256 " + digest.hexdigest().encode() + b"\n")
        f.write(payload)
    return path


def _corrupt(path: Path, why: str) -> CheckpointError:
    return CheckpointError(
        f"cannot resume: {path} is corrupt or truncated ({why}); it is refused rather than resumed "
        f"on damaged data: restore it from a copy, or start a new run"
    )


def _payload(path: Path) -> bytes:
    """The verified payload of a format-2 checkpoint file; CheckpointError if it is not one
    or its checksum does not match, or if the run folder's reader refuses it (a link, not a
    regular file, past its bound: :func:`billiards.files.open_run_file`)."""
    try:
        with open_run_file(path, "checkpoint") as f:
            head = f.read(_HEADER_MAX)
            if (why := compat.checkpoint_format_refusal(head)) is not None:
                raise CheckpointError(f"cannot resume: {path} {why}; this version loads only format {FORMAT_VERSION}. "
                                      f"Finish that run with the commit that wrote it, or start a new run")
            m = _HEADER.match(head)
            if m is None:
                raise _corrupt(path, "no billiards checkpoint header")
            f.seek(m.end())
            payload = f.read()
    except RunFileError as err:
        raise CheckpointError(f"cannot resume: {err}") from None
    digest = hashlib.sha256(m.group(1))
    digest.update(payload)
    if digest.hexdigest() != m.group(3).decode():
        raise _corrupt(path, f"content checksum mismatch: sha256 {digest.hexdigest()[:12]}..., "
                             f"the file says {m.group(3).decode()[:12]}...")
    version = int(m.group(2))
    if version != FORMAT_VERSION:
        raise CheckpointError(
            f"cannot resume: {path} is a checkpoint of format {version}; this version of billiards reads "
            f"format {FORMAT_VERSION}"
        )
    return payload


def load_checkpoint(run_dir: str | Path, keep: bool = False) -> dict[str, Any]:
    """The state saved by :func:`save_checkpoint` in ``run_dir``. Loads tensors and plain
    types only (``weights_only=True``): nothing in the file is executed. Raises
    :class:`CheckpointError` naming the file if it is missing, of another format, corrupt
    (checksum) or holds anything else, or if its content is impossible
    (:func:`check_checkpoint`). ``keep``: hold the state for the next load of the same,
    unchanged file (a run's validation, before the run loads it: the file is read and checked
    once); restoring it into a run lets it go."""
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT_FILE
    if not run_dir.is_dir():
        raise CheckpointError(f"cannot resume: {run_dir} is not a directory")
    if not os.path.lexists(path):
        raise CheckpointError(
            f"cannot resume: {path} does not exist (the run was killed before its first checkpoint, "
            f"every budget.checkpoint_every steps); start a new run instead"
        )
    key = _identity(path)
    if key in _LAST:
        return _LAST[key]
    payload = _payload(path)
    try:
        state = torch.load(io.BytesIO(payload), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise CheckpointError(
            f"cannot resume: {path} holds objects other than tensors and plain data ({first}); "
            f"refusing to load it, since unpickling them could run code"
        ) from None
    except Exception as err:  # torch raises many types for a malformed archive
        raise _corrupt(path, f"{type(err).__name__}: {err}") from None
    if not isinstance(state, dict) or state.get("format_version") != FORMAT_VERSION:
        version = state.get("format_version") if isinstance(state, dict) else None
        raise CheckpointError(
            f"cannot resume: {path} is not a billiards training checkpoint of format {FORMAT_VERSION} (found {version!r})"
        )
    try:
        state = compat.upgrade_checkpoint(state)
    except compat.NewerFormError as err:
        raise CheckpointError(f"cannot resume: {path}: {err}") from None
    missing = [k for k in REQUIRED if k not in state]
    if missing:
        raise CheckpointError(f"cannot resume: {path} lacks {missing}; it is corrupt, start a new run")
    check_checkpoint(state, path)
    if keep:
        _LAST.clear()
        _LAST[key] = state
    return state


# The checkpoint a load kept (load_checkpoint(..., keep=True)), by its file's identity (path, device,
# inode, size, modification time): a run's validation loads its resume= checkpoint before any
# directory is written, and the run then takes it from here instead of reading and checking the
# whole file (replay buffer included) again. Restoring it into a run drops it (RunState.restore).
_LAST: dict[tuple, dict[str, Any]] = {}


def _identity(path: Path) -> tuple:
    st = path.stat()
    return (str(path.resolve()), st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
