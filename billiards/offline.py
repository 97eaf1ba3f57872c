"""Offline datasets in Minari's format: innings played by an agent, every transition with the
gymnasium env's observation, the shot, the reward, the flags and the env's info.

An episode is one inning of the benchmark's ``innings-v1`` protocol (a random rack, continue on a
miss, 10 shots; ``docs/benchmark.md``), played on the gymnasium vector env with raw actions, its
rack and noise from its own seed (``DATASET_SEED`` + the inning's index: far from every
benchmark track's held-out seeds). The agent is any spec the benchmark takes
(:func:`billiards.bench.adapters.resolve_agent`), under the track's simulation budget. The
datasets of the issue, per noise preset (``none``, ``fastfiz``):

* ``expert``: the default search of ``search.py`` for that noise (``search:h2`` exact -- the
  default's h2 over the geometric proposer --, ``search:default`` under noise: the position-aware
  robust search over the learned shot ranker);
* ``medium``: SAC with the aim constraint and the carom features (``results/policies/base``
  exact, ``results/policies/fastfiz_aim_features`` under fastfiz, seed 0);
* ``random``: uniform raw shots.

``python -m billiards.offline generate --dataset expert --noise none --shots 200000 --out DIR``
plays blocks of innings side by side and writes each block to ``DIR/blocks/`` as it ends (a
killed run keeps its finished blocks; the same command resumes with the rest);
``python -m billiards.offline build DIR`` writes the Minari dataset
(``billiards/<noise>/<dataset>-v0``) under ``DIR/minari`` and prints its size and the sha256 of its content;
``minari.load_dataset`` reads it with ``MINARI_DATASETS_PATH=DIR/minari``, and TorchRL's
``MinariExperienceReplay(..., load_from_local_minari=True)`` too.

Every input is checked before anything is written and every file when it is read (the
"inputs" section below; docs/datasets.md, "Bounds and checks"): a refusal is one sentence,
``Error: ...``, never a traceback.

The actions are the raw shots as played (float64 theta, p, a, b): the searches' angles come
from ``atan2`` (within one turn either way), so the dataset's action space spans
``[-2pi, 2pi]`` for the angle, not the env's ``[0, 2pi]``; the simulator plays either.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import re
import sys
import zipfile
from pathlib import Path

import numpy as np

from billiards.files import atomic_write_bytes, display_path

DATASET_SEED = 9_000_000
BLOCK = 100  # innings played side by side, one file each
SHOTS = 10  # shots per inning (the innings-v1 protocol)
NOISES = ("none", "fastfiz")
DATASETS = {
    "expert": {"none": "search:h2", "fastfiz": "search:default"},
    "medium": {"none": "results/policies/base/seed0.pt", "fastfiz": "results/policies/fastfiz_aim_features/seed0.pt"},
    "random": {"none": "random", "fastfiz": "random"},
}
# the env's info keys a dataset keeps: their shape per step and dtype
INFO_LAYOUT = {"score": ((), np.bool_), "foul": ((), np.bool_), "miss": ((), np.bool_), "first_contact": ((), np.int64),
               "second_red": ((), np.int64), "cushions": ((), np.int64), "positions": ((4, 2), np.float64),
               "raw_action": ((4,), np.float64), "commanded_action": ((4,), np.float64)}
INFO = tuple(INFO_LAYOUT)
# the datasets' action space: the raw shot, its angle within one turn either way (module docstring)
ACTION_LOW, ACTION_HIGH = np.array([-2 * math.pi, 0.0, -1.0, -1.0]), np.array([2 * math.pi, 1.0, 1.0, 1.0])


def dataset_id(dataset: str, noise: str) -> str:
    return f"billiards/{noise}/{dataset}-v0"


def track_for(noise: str):
    """The ``innings-v1`` track with the dataset's noise and seeds (its budget for a search)."""
    from billiards.bench.tracks import get_track

    return dataclasses.replace(get_track("innings-v1"), noise=noise, seed=DATASET_SEED, name="innings-v1")


def play_block(agent, track, first: int, n: int) -> dict[str, np.ndarray]:
    """Innings ``first .. first + n - 1``, played by the benchmark's own loop
    (:func:`billiards.bench.protocols.play_innings`): observations (n, T+1, D), actions (n, T, 4),
    rewards, terminations, truncations (n, T) and the env's info keys :data:`INFO` (n, T+1, ...;
    the entry before the first shot holds the rack and zeros)."""
    from billiards.bench.protocols import play_innings

    out = {"observations": [], "actions": [], "rewards": [], "terminations": [], "truncations": []}
    infos = {k: [] for k in INFO}
    racks = []

    def record(t, before, obs, raw, step):
        next_obs, reward, term, trunc, info = step
        if t < track.shots - 1 and (term.any() or trunc.any()):
            raise RuntimeError("an inning ended before its last shot: the protocol continues on a miss")
        if t == 0:
            out["observations"].append(obs)
            racks.append(before)
        for key, value in zip(("observations", "actions", "rewards", "terminations", "truncations"),
                              (next_obs, np.asarray(raw, dtype=np.float64), reward, term, trunc)):
            out[key].append(value)
        for k in INFO:
            infos[k].append(info[k])

    play_innings(agent, track, first, n, on_step=record)
    arrays = {k: np.stack(v, axis=1) for k, v in out.items()}
    for k, v in infos.items():  # row 0, before the first shot: the rack, zeros for the rest
        arrays[f"info/{k}"] = np.stack([racks[0] if k == "positions" else np.zeros_like(v[0]), *v], axis=1)
    return arrays


def _block_path(out: Path, index: int) -> Path:
    return Path(out) / "blocks" / f"block{index:05d}.npz"


# ----------------------------------------------------------------------------- inputs
#
# One mechanism checks what the datasets' commands are given, before anything is written, and
# every file when it is read: the options against :data:`LIMITS` and the choices, the agent by
# building it, the folders by looking (``billiards.app_config.path_problem``), ``dataset.json``
# against :data:`MANIFEST`, each block against the episodes its manifest says it holds
# (:func:`block_layout`). Each refusal is one sentence naming the option or the file and what is
# wrong -- never a file's contents -- raised as :class:`DatasetError` (``Error: ...``, exit
# status 1, no traceback: the project's convention for its command lines).


class DatasetError(SystemExit):
    """A bad input to the datasets' commands: ``Error: <one sentence>``. A ``SystemExit``, so
    that a command line, or a script calling these functions, ends with the sentence and no
    traceback."""

    def __init__(self, problem: str):
        super().__init__(f"Error: {problem}")


MANIFEST_FILE = "dataset.json"
MAX_SHOTS = 2_000_000
LIMITS = {  # option -> (lowest, highest, why the highest)
    "--shots": (1, MAX_SHOTS, "ten times the shipped datasets: about 8 GiB in Minari's format, and build holds every "
                              "episode in memory, about 1 GiB per 200,000 shots"),
    "--updates": (1, 10_000_000, "gradient steps, about a day on one core; the baseline takes 20,000"),
    "--seed": (0, 2**31 - 1, "a 31-bit seed"),
}
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")  # a dataset's name: part of its Minari id and of a path
# dataset.json: key -> type; "commit" may be there besides (the code that played the blocks)
MANIFEST = {"dataset_id": str, "dataset": str, "noise": str, "agent": str, "physics": str, "shots_per_inning": int,
            "block": int, "blocks": int, "seed": int, "budget": int}
MAX_MANIFEST_BYTES = 1 << 20


def option_problem(value, option: str) -> str | None:
    """Why ``value`` is no valid integer ``option`` (:data:`LIMITS`), or None."""
    lo, hi, why = LIMITS[option]
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        return f"{option} must be a whole number, got {str(value)[:40]!r}"
    if value < lo:
        return f"{option} must be at least {lo:,}, got {value}"
    if value > hi:
        return f"{option} must be at most {hi:,} ({why}), got {value}"
    return None


def _check(problem: str | None) -> None:
    if problem is not None:
        raise DatasetError(problem)


def _kind(value) -> str:
    """What a JSON value is, in words (not what it holds)."""
    if value is None:
        return "null"
    return {bool: "a boolean", int: "a number", float: "a number", str: "a string", list: "a list",
            dict: "an object"}.get(type(value), type(value).__name__)


def manifest_problem(manifest) -> str | None:
    """Why ``manifest`` (dataset.json, parsed) describes no dataset this code reads, or None."""
    from billiards.physics import PRESETS
    from billiards.physics.noise import NOISE_PRESETS

    if not isinstance(manifest, dict):
        return f"not a JSON object but {_kind(manifest)}"
    missing = [k for k in MANIFEST if k not in manifest]
    if missing:
        return f"lacks {', '.join(missing)}"
    for key, kind in MANIFEST.items():
        value = manifest[key]
        if isinstance(value, bool) or not isinstance(value, kind):
            return f"{key} must be {'a string' if kind is str else 'a whole number'}, got {_kind(value)}"
    if "commit" in manifest and not isinstance(manifest["commit"], str):
        return f"commit must be a string, got {_kind(manifest['commit'])}"
    if not NAME.fullmatch(manifest["dataset"]):
        return "dataset is no dataset name (letters, digits, _ and -, at most 64)"
    if manifest["noise"] not in NOISE_PRESETS:
        return f"noise must be one of {', '.join(NOISE_PRESETS)}"
    if manifest["physics"] not in PRESETS:
        return f"physics must be one of {', '.join(sorted(PRESETS))}"
    if manifest["dataset_id"] != dataset_id(manifest["dataset"], manifest["noise"]):
        return f"dataset_id is not {dataset_id(manifest['dataset'], manifest['noise'])}, its dataset's and noise's"
    for key, want in (("shots_per_inning", SHOTS), ("block", BLOCK), ("seed", DATASET_SEED)):
        if manifest[key] != want:
            return f"{key} is {manifest[key]}; this code plays and reads {key} {want}"
    if not 1 <= manifest["blocks"] <= _blocks(MAX_SHOTS):
        return f"blocks must lie in 1..{_blocks(MAX_SHOTS):,}, got {manifest['blocks']}"
    if manifest["budget"] < 1:
        return f"budget must be at least 1, got {manifest['budget']}"
    return None


def _blocks(shots: int) -> int:
    return math.ceil(shots / (SHOTS * BLOCK))


def _folder_problem(out: Path) -> str | None:
    """Why ``out`` is no dataset folder to read, or None."""
    where = display_path(out)
    if not os.path.lexists(out):
        return f"{where}: no such folder"
    if not out.is_dir():
        return f"{where}: a file, not a dataset folder"
    path = out / MANIFEST_FILE
    if not os.path.lexists(path):
        return f"{where}: holds no {MANIFEST_FILE}, so no dataset of python -m billiards.offline generate"
    if not path.is_file():
        return f"{display_path(path)}: not a file"
    return None


def read_manifest(out: Path) -> dict:
    """``out/dataset.json``, checked (:func:`manifest_problem`); a :class:`DatasetError` names
    the folder or the file and what is wrong."""
    out = Path(out)
    _check(_folder_problem(out))
    path = out / MANIFEST_FILE
    where = display_path(path)
    try:
        with open(path, "rb") as f:
            data = f.read(MAX_MANIFEST_BYTES + 1)
    except OSError as err:
        raise DatasetError(f"{where}: cannot be read ({err.strerror})") from None
    if len(data) > MAX_MANIFEST_BYTES:
        raise DatasetError(f"{where}: damaged: larger than {MAX_MANIFEST_BYTES:,} bytes, far more than a manifest")
    try:
        manifest = json.loads(data)
    except json.JSONDecodeError as err:
        raise DatasetError(f"{where}: damaged: not JSON (line {err.lineno}, column {err.colno}); move the folder aside "
                           f"and generate the dataset again") from None
    except (ValueError, RecursionError):  # not UTF-8, or nested past the parser's stack
        raise DatasetError(f"{where}: damaged: not JSON text; move the folder aside and generate the dataset again") from None
    problem = manifest_problem(manifest)
    if problem:
        raise DatasetError(f"{where}: damaged: {problem}; move the folder aside and generate the dataset again")
    return manifest


def obs_dim(noise: str) -> int:
    """The gymnasium env's observation size under ``noise``: the table, and under variable noise
    the next shot's level."""
    from billiards import domain
    from billiards.physics.noise import get_noise

    return domain.OBS_DIM + int(get_noise(noise).is_variable)


def block_layout(manifest: dict) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Each array a block of ``manifest``'s dataset holds: its shape ((innings, steps, ...): T
    actions, rewards and flags to T + 1 observations and infos) and dtype."""
    n, T = manifest["block"], manifest["shots_per_inning"]
    layout = {"observations": ((n, T + 1, obs_dim(manifest["noise"])), np.float32), "actions": ((n, T, 4), np.float64),
              "rewards": ((n, T), np.float64), "terminations": ((n, T), np.bool_), "truncations": ((n, T), np.bool_),
              **{f"info/{k}": ((n, T + 1, *shape), dtype) for k, (shape, dtype) in INFO_LAYOUT.items()}}
    return {k: (shape, np.dtype(dtype)) for k, (shape, dtype) in layout.items()}


def _headers(path: Path) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """The shape and dtype of each array of an ``.npz`` file, from the arrays' headers alone."""
    from numpy.lib import format as npy

    headers = {}
    with zipfile.ZipFile(path) as z:
        for info in z.infolist():
            with z.open(info) as f:
                version = npy.read_magic(f)
                read = {(1, 0): npy.read_array_header_1_0, (2, 0): npy.read_array_header_2_0}.get(version)
                if read is None:
                    raise ValueError(f"array format {version}")
                shape, _, dtype = read(f)
            headers[info.filename.removesuffix(".npy")] = (shape, dtype)
    return headers


def _unreadable(where: str, err: BaseException) -> DatasetError:
    return DatasetError(f"{where}: not a readable block (truncated or damaged: {type(err).__name__}); remove it and run "
                        f"generate again to play it again")


def read_block(out: Path, index: int, manifest: dict) -> dict[str, np.ndarray]:
    """Block ``index`` of the dataset in ``out``, checked against the episodes ``manifest`` says
    it holds: the arrays of :func:`block_layout`, no more, no fewer, each of its shape and dtype
    (read from the headers before any data), every float finite, the shots within the datasets'
    action space. A :class:`DatasetError` names the file and what is wrong."""
    path = _block_path(out, index)
    where = display_path(path)
    if not path.is_file():
        raise DatasetError(f"{where}: missing; run generate again to play it")
    layout = block_layout(manifest)
    # A damaged zip raises whatever its damage makes zipfile, zlib or NumPy raise (BadZipFile,
    # EOFError, zlib.error, ValueError, NotImplementedError for an unknown compression ...).
    try:
        headers = _headers(path)
    except Exception as err:  # noqa: BLE001
        raise _unreadable(where, err) from None
    missing = [k for k in layout if k not in headers]
    if missing:
        raise DatasetError(f"{where}: lacks {', '.join(missing)}; remove it and run generate again to play it again")
    extra = [k for k in headers if k not in layout]
    if extra:
        raise DatasetError(f"{where}: holds {len(extra)} array(s) a block does not ({', '.join(sorted(extra)[:3])}); remove it "
                           f"and run generate again to play it again")
    for key, (shape, dtype) in layout.items():
        got_shape, got_dtype = headers[key]
        if got_shape != shape or got_dtype != dtype:
            n, T = manifest["block"], manifest["shots_per_inning"]
            raise DatasetError(f"{where}: {key} is {got_dtype} of shape {got_shape}, where {n} innings of {T} shots need "
                               f"{dtype} of shape {shape}; remove it and run generate again to play it again")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in layout}
    except Exception as err:  # noqa: BLE001
        raise _unreadable(where, err) from None
    for key, a in arrays.items():
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise DatasetError(f"{where}: {key} holds NaN or an infinity; remove it and run generate again to play it again")
    a = arrays["actions"]
    if ((a < ACTION_LOW) | (a > ACTION_HIGH)).any():
        raise DatasetError(f"{where}: actions hold shots outside the datasets' action space (the angle within 2 pi either way, "
                           f"power 0 to 1, spin -1 to 1); remove it and run generate again to play it again")
    return arrays


def _out_problem(out: Path, option: str = "--out") -> str | None:
    """Why no dataset can be written at ``out``: a file, under a file, not writable, a name too
    long (looked at, nothing created), or a folder of other files; None if it can."""
    from billiards.app_config import path_problem

    problem = path_problem(str(out), f"{option} {display_path(out)}")
    if problem or not out.is_dir():
        return problem
    names = os.listdir(out)
    if names and MANIFEST_FILE not in names:
        return (f"{option} {display_path(out)}: holds {len(names)} file(s) and no {MANIFEST_FILE}, so no dataset; choose a "
                f"new or empty folder")
    if os.path.lexists(out / "blocks") and not (out / "blocks").is_dir():
        return f"{option} {display_path(out)}: its blocks is a file, not a folder"
    return None


def _played(out: Path) -> list[Path]:
    blocks = out / "blocks"
    return sorted(blocks.glob("block[0-9][0-9][0-9][0-9][0-9].npz")) if blocks.is_dir() else []


def _differences(held: dict, manifest: dict) -> str:
    short = lambda v: repr(v) if len(repr(v)) <= 60 else repr(v)[:56] + "...'"  # noqa: E731
    keys = [k for k in manifest if held.get(k) != manifest[k]]
    return "; ".join(f"{k} {short(held.get(k))} there, {short(manifest[k])} here" for k in keys[:3])


def _plan(dataset: str, noise: str, shots: int, out: Path, agent_spec: str | None):
    """Every input of :func:`generate` checked, nothing written: the manifest, the track, the
    blocks to play, the agent (built; None when nothing is left to play) and whether
    dataset.json is to be written."""
    _check(option_problem(shots, "--shots"))
    from billiards.physics.noise import NOISE_PRESETS

    if not isinstance(noise, str) or not isinstance(dataset, str):
        raise DatasetError(f"--noise and --dataset must be names, got {type(noise).__name__} and {type(dataset).__name__}")
    if agent_spec is None:
        if noise not in NOISES:
            raise DatasetError(f"--noise must be one of {', '.join(NOISES)} (or give --agent), got {str(noise)[:40]!r}")
        if dataset not in DATASETS:
            raise DatasetError(f"--dataset must be one of {', '.join(DATASETS)} (or give --agent), got {str(dataset)[:40]!r}")
    else:
        if not isinstance(agent_spec, str) or not agent_spec.strip():
            raise DatasetError("--agent must name an agent (docs/benchmark.md lists the specs), got an empty one")
        if noise not in NOISE_PRESETS:
            raise DatasetError(f"--noise must be one of {', '.join(NOISE_PRESETS)}, got {str(noise)[:40]!r}")
        if not NAME.fullmatch(dataset):
            raise DatasetError(f"--dataset must be a name of letters, digits, _ and - (at most 64, a letter or digit "
                               f"first), got {str(dataset)[:40]!r}")
    out = Path(out)
    _check(_out_problem(out))
    spec = agent_spec or DATASETS[dataset][noise]
    track = track_for(noise)
    blocks = _blocks(shots)
    manifest = {"dataset_id": dataset_id(dataset, noise), "dataset": dataset, "noise": noise, "agent": spec,
                "physics": track.physics, "shots_per_inning": SHOTS, "block": BLOCK, "blocks": blocks,
                "seed": DATASET_SEED, "budget": track.budget}
    write = True
    if os.path.lexists(out / MANIFEST_FILE):
        held = {k: v for k, v in read_manifest(out).items() if k != "commit"}
        if held == manifest:
            write = False
        elif _played(out):  # a manifest without a finished block holds nothing: the new command's replaces it
            raise DatasetError(f"{display_path(out)} holds another dataset ({_differences(held, manifest)}); give another --out")
    todo = [b for b in range(blocks) if not _block_path(out, b).exists()]
    for b in sorted(set(range(blocks)) - set(todo)):  # the finished blocks are checked before more are played beside them
        read_block(out, b, manifest)
    if not todo:
        return manifest, track, todo, None, write
    from billiards.bench.adapters import resolve_agent

    try:
        agent = resolve_agent(spec, track)
    except (ValueError, OSError) as err:  # AgentError is a ValueError; a file it names may not be readable
        raise DatasetError(f"{'--agent' if agent_spec else f'--dataset {dataset} --noise {noise}'}: {err}") from None
    return manifest, track, todo, agent, write


def generate(dataset: str, noise: str, shots: int, out: Path, agent_spec: str | None = None, progress: bool = True) -> dict:
    """Play ``shots`` shots (rounded up to whole blocks of innings) into ``out``; resumes.
    Every input is checked first (:func:`_plan`): a refused one leaves nothing written."""
    out = Path(out)
    manifest, track, todo, agent, write = _plan(dataset, noise, shots, out, agent_spec)
    if not todo:
        return manifest
    import time

    from billiards.bench.adapters import AgentError
    from billiards.provenance import git_commit

    spec, blocks = manifest["agent"], manifest["blocks"]
    print(f"{manifest['dataset_id']}: {blocks} blocks of {BLOCK} innings x {SHOTS} shots by {spec}; "
          f"{blocks - len(todo)} done, {len(todo)} to play -> {out}", flush=True)
    start = time.perf_counter()
    try:
        (out / "blocks").mkdir(parents=True, exist_ok=True)
        if write:
            atomic_write_bytes(out / MANIFEST_FILE, json.dumps({**manifest, "commit": git_commit()}, indent=1).encode())
        for i, b in enumerate(todo):
            try:
                arrays = play_block(agent, track, b * BLOCK, BLOCK)
            except AgentError as err:
                raise DatasetError(f"the agent {spec[:80]!r} failed in block {b + 1}: {err}; the {blocks - len(todo) + i} "
                                   f"finished blocks are kept") from None
            path = _block_path(out, b)
            tmp = path.with_suffix(".tmp.npz")
            np.savez(tmp, **arrays)
            os.replace(tmp, path)
            if progress:
                left = (time.perf_counter() - start) / (i + 1) * (len(todo) - i - 1)
                print(f"block {b + 1}/{blocks} written; about {left / 60:.1f} min left", file=sys.stderr, flush=True)
    except OSError as err:
        raise DatasetError(f"{display_path(err.filename or out)}: cannot be written ({err.strerror or err}); the finished "
                           f"blocks are kept") from None
    return manifest


def episodes(out: Path):
    """The dataset's innings as Minari episode buffers, in seed order; each block checked as it
    is read (:func:`read_block`)."""
    manifest = read_manifest(out)
    for b in range(manifest["blocks"]):
        arrays = read_block(out, b, manifest)
        for i in range(manifest["block"]):
            yield {"observations": arrays["observations"][i], "actions": arrays["actions"][i],
                   "rewards": arrays["rewards"][i], "terminations": arrays["terminations"][i],
                   "truncations": arrays["truncations"][i], "id": b * manifest["block"] + i,
                   "seed": manifest["seed"] + b * manifest["block"] + i,
                   "infos": {k.split("/", 1)[1]: arrays[k][i] for k in arrays if k.startswith("info/")}}


def build(out: Path, root: Path | None = None):
    """The Minari dataset of the blocks in ``out`` (every block must be there and sound), under
    ``root`` (default ``out/minari``); returns it. Nothing is written until every block has
    been read and checked."""
    out = Path(out)
    manifest = read_manifest(out)
    missing = [b for b in range(manifest["blocks"]) if not _block_path(out, b).exists()]
    if missing:
        raise DatasetError(f"{display_path(out)}: {len(missing)} of {manifest['blocks']} blocks not played yet; run generate again")
    from billiards.app_config import path_problem

    root = Path(root) if root is not None else out / "minari"
    _check(path_problem(str(root), f"--root {display_path(root)}"))
    root = root.resolve()  # Minari resolves a relative one against itself
    if os.path.lexists(root / manifest["dataset_id"]):
        raise DatasetError(f"{root / manifest['dataset_id']} exists already; remove it to build the dataset again")
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    from billiards import GYM_ID

    buffers = [EpisodeBuffer(**ep) for ep in episodes(out)]
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    env = gym.make(GYM_ID, start="random", on_miss="continue", max_shots=SHOTS, physics=manifest["physics"],
                   noise=manifest["noise"], normalize_actions=False)
    action_space = gym.spaces.Box(low=ACTION_LOW, high=ACTION_HIGH, dtype=np.float64)
    import warnings

    with warnings.catch_warnings():  # no e-mail address and no URL of the code: the commit names the code
        warnings.filterwarnings("ignore", message=".*(author_email|code_permalink).*is set to None", category=UserWarning)
        return minari.create_dataset_from_buffers(
            dataset_id=manifest["dataset_id"], buffer=buffers, env=env, action_space=action_space,
            algorithm_name=manifest["agent"], author="billiards", code_permalink=f"billiards commit {manifest.get('commit')}",
            description=(f"Korean 4-ball billiards, {manifest['noise']} execution noise: innings of the innings-v1 protocol "
                         f"(random rack, continue on a miss, {SHOTS} shots) played by {manifest['agent']}; episode k from seed "
                         f"{manifest['seed']} + k"), eval_env=env)


def checksum(out: Path) -> str:
    """sha256 over the dataset's content: every block's arrays in order (name, dtype, shape and
    bytes), so the same command gives the same checksum whatever Minari's files hold besides."""
    h = hashlib.sha256()
    manifest = read_manifest(out)
    for b in range(manifest["blocks"]):
        arrays = read_block(out, b, manifest)
        for name in sorted(arrays):
            a = np.ascontiguousarray(arrays[name])
            h.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
            h.update(a.tobytes())
    return h.hexdigest()


# The offline baseline: TorchRL's IQL (implicit Q-learning) on a dataset read with
# minari.load_dataset into a TorchRL replay buffer (TorchRL 0.14.1's MinariExperienceReplay reads
# these datasets' layout but not their values: docs/datasets.md), scored on the benchmark track of
# the dataset's noise.
IQL_TRACK = {"none": "innings-v1", "fastfiz": "p1-fastfiz-v1"}
# What the learner sees and emits: ``raw`` the gymnasium env's observation (28 floats) and
# normalised action box (the angle over the whole turn); ``aim_features`` what the project's own
# agents use (env=aim_features): the observation with the carom features (32 floats) and the
# aim-constrained action (u inside the nearest red's window, p, a, b), both from the table the
# observation holds (billiards.domain.observed_positions).
SPACES = ("raw", "aim_features")
IQL_SETTINGS = {"batch_size": 256, "lr": 3e-4, "gamma": 0.9, "tau": 0.005, "expectile": 0.7, "temperature": 3.0,
                "hidden_sizes": [256, 256]}


EDGE = 1.0 - 1e-3  # a learner's normalised actions are kept this far inside [-1, 1] (a squashed Gaussian's log-likelihood is finite)


def normalized_actions(actions: np.ndarray) -> np.ndarray:
    """The datasets' raw shots (theta within one turn either way, p, a, b) as the normalised box
    [-1, 1]^4 of the gymnasium env (theta taken into [0, 2 pi) first), kept :data:`EDGE` inside
    it."""
    from billiards import domain

    raw = np.array(actions, dtype=np.float64)
    raw[..., 0] = np.mod(raw[..., 0], 2 * math.pi)
    return np.clip(domain.normalize_action(raw), -EDGE, EDGE).astype(np.float32)


def _radius(R: float | None) -> float:
    from billiards.physics import DEFAULT_PARAMS

    return DEFAULT_PARAMS.ball_radius if R is None else float(R)


def track_radius(track: str) -> float:
    """The ball radius of a benchmark track's table (where a learner's aim-space policy plays)."""
    from billiards.bench import get_track
    from billiards.physics import get_params

    return get_params(get_track(track).physics).ball_radius


def _check_space(space: str) -> None:
    if space not in SPACES:
        raise ValueError(f"space must be one of {', '.join(SPACES)}, got {space!r}")


def space_observation(obs: np.ndarray, space: str) -> np.ndarray:
    """The gymnasium env's observations (..., 28) as the learner of ``space`` sees them
    (:data:`SPACES`), float32: themselves, or under ``aim_features`` the observed table's
    observation with the carom features (..., 32)."""
    from billiards import domain

    _check_space(space)
    if space == "raw":
        return np.asarray(obs, dtype=np.float32)
    return domain.observation(domain.observed_positions(obs), extra_features=True)


def space_action(obs: np.ndarray, actions: np.ndarray, space: str, R: float | None = None) -> np.ndarray:
    """Raw shots (..., 4) played on the tables of observations (..., 28) as the learner of
    ``space`` emits them, float32 in [-1, 1]^4 kept :data:`EDGE` inside it: the env's normalised
    box, or under ``aim_features`` the aim-constrained action (a shot aimed outside the nearest
    red's window clipped to the window's edge; the window of balls of radius ``R``, the table's:
    default the default table's)."""
    from billiards import domain

    _check_space(space)
    if space == "raw":
        return normalized_actions(actions)
    R = _radius(R)
    return np.clip(domain.normalized_aim_action(domain.observed_positions(obs), actions, R), -EDGE, EDGE).astype(np.float32)


def space_agent(policy, space: str, name: str, R: float | None = None):
    """A benchmark agent (:class:`~billiards.bench.adapters.CallableAgent`) of ``policy``, a NumPy
    function from the learner's observations (:func:`space_observation`) to its normalised
    actions in ``space``: raw, the env's own normalised box; under ``aim_features`` mapped back to
    the raw shot on the observed table (:func:`billiards.domain.raw_action`, balls of radius
    ``R``: the table it plays on; default the default table's)."""
    from billiards import domain
    from billiards.bench.adapters import CallableAgent

    _check_space(space)
    R = _radius(R)

    def act(obs):
        obs = np.asarray(obs)
        a = policy(space_observation(obs[..., :domain.OBS_DIM], space))
        return a if space == "raw" else domain.raw_action(a, domain.observed_positions(obs), R, constrain_aim=True,
                                                          normalized=True)

    return CallableAgent(act, name, normalized=space == "raw")


def _minari_episodes(directory: Path, manifest: dict):
    """The episodes of the Minari dataset built in ``directory`` (``MINARI_DATASETS_PATH`` set),
    read with ``minari.load_dataset``: each episode's observations, actions, rewards and flags,
    checked as the blocks are (their shapes, finite values), and as many as the manifest says.
    A :class:`DatasetError` names the dataset and what is wrong."""
    import minari

    where = display_path(Path(directory) / "minari" / manifest["dataset_id"])
    layout = {k: shape[1:] for k, (shape, _) in block_layout(manifest).items() if "/" not in k}
    damaged = lambda err: DatasetError(f"{where}: not a readable Minari dataset (damaged: {type(err).__name__}); "  # noqa: E731
                                       f"remove it and build it again")
    # Minari's HDF5 files: whatever their damage makes Minari or h5py raise (OSError, KeyError, ValueError ...)
    try:
        episodes = iter(minari.load_dataset(manifest["dataset_id"]).iterate_episodes())
    except Exception as err:  # noqa: BLE001
        raise damaged(err) from None
    count = 0
    while True:
        try:
            ep = next(episodes, None)
            arrays = None if ep is None else {k: np.asarray(getattr(ep, k)) for k in layout}
        except Exception as err:  # noqa: BLE001
            raise damaged(err) from None
        if arrays is None:
            break
        for key, shape in layout.items():
            a = arrays[key]
            if a.shape != shape:
                raise DatasetError(f"{where}: episode {count}'s {key} is of shape {a.shape}, where an inning of "
                                   f"{manifest['shots_per_inning']} shots needs {shape}; remove it and build it again")
            if a.dtype.kind in "fc" and not np.isfinite(a).all():
                raise DatasetError(f"{where}: episode {count}'s {key} holds NaN or an infinity; remove it and build it again")
        count += 1
        yield arrays
    want = manifest["blocks"] * manifest["block"]
    if count != want:
        raise DatasetError(f"{where}: holds {count} episodes where {MANIFEST_FILE} says {want}; remove it and build it again")


def transitions(directory: Path, space: str = "raw"):
    """Every transition of the Minari dataset built in ``directory``, read with
    ``minari.load_dataset``, as one TensorDict in the learner's ``space`` (:func:`space_observation`,
    :func:`space_action`):
    observation, action (normalised), next observation, reward, done and terminated."""
    import torch
    from tensordict import TensorDict

    from billiards.physics import get_params

    directory = Path(directory)
    manifest = read_manifest(directory)
    root = (directory / "minari").resolve()
    if not (root / manifest["dataset_id"]).is_dir():
        raise DatasetError(f"{display_path(directory)}: no Minari dataset yet; run python -m billiards.offline build "
                           f"{display_path(directory)}")
    os.environ["MINARI_DATASETS_PATH"] = str(root)
    parts = {k: [] for k in ("obs", "next", "action", "reward", "terminated", "truncated")}
    R = get_params(manifest["physics"]).ball_radius  # the aim window of the table the dataset was played on
    for arrays in _minari_episodes(directory, manifest):
        x = space_observation(arrays["observations"], space)
        parts["obs"].append(x[:-1])
        parts["next"].append(x[1:])
        parts["action"].append(space_action(arrays["observations"][:-1], arrays["actions"], space, R))
        parts["reward"].append(arrays["rewards"])
        parts["terminated"].append(arrays["terminations"])
        parts["truncated"].append(arrays["truncations"])
    cat = {k: torch.from_numpy(np.concatenate(v)) for k, v in parts.items()}
    n = cat["obs"].shape[0]
    flag = lambda x: x.bool().reshape(n, 1)
    return TensorDict({"observation": cat["obs"].float(), "action": cat["action"],
                       "next": {"observation": cat["next"].float(), "reward": cat["reward"].float().reshape(n, 1),
                                "terminated": flag(cat["terminated"]),
                                "done": flag(cat["terminated"]) | flag(cat["truncated"])}}, batch_size=[n])


def _check_iql(directory: Path, updates: int, out: Path, seed: int) -> dict:
    """Every input of :func:`train_iql` checked, nothing written; returns the dataset's manifest.
    ``out`` must be new or empty: the policy is not saved, and a scorecard left there by another
    run would be continued as this one's."""
    from billiards.app_config import path_problem

    for value, option in ((updates, "--updates"), (seed, "--seed")):
        _check(option_problem(value, option))
    _check(path_problem(str(out), f"--out {display_path(out)}"))
    if out.is_dir() and os.listdir(out):
        raise DatasetError(f"--out {display_path(out)}: not empty (another run's iql.json or scorecard would be mixed with "
                           f"this one's); choose a new or empty folder")
    manifest = read_manifest(directory)
    if not (directory / "minari" / manifest["dataset_id"]).is_dir():
        raise DatasetError(f"{display_path(directory)}: no Minari dataset yet; run python -m billiards.offline build "
                           f"{display_path(directory)}")
    return manifest


def train_iql(directory: Path, updates: int, out: Path, seed: int = 0, progress: bool = True, space: str = "raw") -> dict:
    """IQL (TorchRL's ``IQLLoss``, :data:`IQL_SETTINGS`) for ``updates`` gradient steps on the
    dataset built in ``directory`` in the learner's ``space`` (:func:`transitions`), then its
    deterministic policy (mapped back to the raw shot on the observed table) scored on
    the dataset noise's track (:data:`IQL_TRACK`) by the benchmark (``out/scorecard``); writes
    ``out/iql.json`` (settings, CPU seconds, the scorecard's figures) and returns it."""
    directory, out, cfg = Path(directory), Path(out), IQL_SETTINGS
    _check_space(space)
    manifest = _check_iql(directory, updates, out, seed)
    import time

    import torch
    from tensordict.nn import NormalParamExtractor, TensorDictModule
    from torchrl.data import Bounded, LazyTensorStorage, ReplayBuffer
    from torchrl.modules import ProbabilisticActor, TanhNormal, ValueOperator
    from torchrl.objectives import IQLLoss, SoftUpdate, ValueEstimators

    from billiards.bench import evaluate
    from billiards.rl.learners import mlp

    torch.manual_seed(seed)
    data = transitions(directory, space)
    rb = ReplayBuffer(storage=LazyTensorStorage(data.shape[0]), batch_size=cfg["batch_size"])
    rb.extend(data)
    dim, ones = int(data["observation"].shape[-1]), torch.ones(4)
    actor = ProbabilisticActor(
        TensorDictModule(torch.nn.Sequential(mlp(dim, 8, cfg["hidden_sizes"]), NormalParamExtractor()),
                         in_keys=["observation"], out_keys=["loc", "scale"]),
        in_keys=["loc", "scale"], out_keys=["action"], spec=Bounded(-ones, ones, shape=(4,)),
        distribution_class=TanhNormal, distribution_kwargs={"low": -ones, "high": ones})
    q = ValueOperator(mlp(dim + 4, 1, cfg["hidden_sizes"]), in_keys=["observation", "action"])
    v = ValueOperator(mlp(dim, 1, cfg["hidden_sizes"]), in_keys=["observation"])
    loss = IQLLoss(actor, q, v, expectile=cfg["expectile"], temperature=cfg["temperature"])
    loss.make_value_estimator(ValueEstimators.TD0, gamma=cfg["gamma"])
    target = SoftUpdate(loss, tau=cfg["tau"])
    optimizer = torch.optim.Adam(loss.parameters(), lr=cfg["lr"])
    start, cpu = time.perf_counter(), time.process_time()
    for i in range(updates):
        losses = loss(rb.sample())
        total = losses["loss_actor"] + losses["loss_qvalue"] + losses["loss_value"]
        optimizer.zero_grad()
        total.backward()
        optimizer.step()
        target.step()
        if progress and (i + 1) % max(1, updates // 10) == 0:
            shown = ", ".join(f"{k} {float(losses[f'loss_{k}'].detach()):.3f}" for k in ("actor", "qvalue", "value"))
            print(f"iql {i + 1}/{updates}: {shown}", file=sys.stderr, flush=True)
    train_cpu = time.process_time() - cpu
    net = actor.module[0].module

    def policy(x):
        with torch.no_grad():
            return torch.tanh(net(torch.as_tensor(x, dtype=torch.float32))[0]).numpy()

    track = IQL_TRACK[manifest["noise"]]
    flag = "" if space == "raw" else f" --space {space}"
    card = evaluate(space_agent(policy, space, f"iql:{space}", track_radius(track)), track, out=out / "scorecard", progress=False,
                    command=f"python -m billiards.offline iql {directory} --updates {updates} --seed {seed}{flag} --out {out}")
    record = {"dataset_id": manifest["dataset_id"], "updates": updates, "seed": seed, "space": space, "settings": cfg,
              "train_cpu_seconds": round(train_cpu, 1), "train_wall_seconds": round(time.perf_counter() - start, 1),
              "track": track, **{k: card[k] for k in ("success_per_shot", "points_per_inning", "foul_per_shot", "ms_per_decision")}}
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(out / "iql.json", (json.dumps(record, indent=2) + "\n").encode())
    return record


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m billiards.offline", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    g = sub.add_parser("generate", help="play the dataset's innings into --out (resumable)")
    g.add_argument("--dataset", default="expert", help=f"one of {', '.join(DATASETS)} (default expert)")
    g.add_argument("--noise", default="none", help=f"one of {', '.join(NOISES)} (default none)")
    g.add_argument("--shots", type=int, default=200_000,
                   help=f"shots to play, in whole blocks of innings (default 200000, at most {MAX_SHOTS})")
    g.add_argument("--agent", default=None, help="another agent spec (docs/benchmark.md) instead of the dataset's own")
    g.add_argument("--out", type=Path, required=True, help="the dataset's folder (blocks/, dataset.json)")
    g.add_argument("--no-progress", action="store_true")
    b = sub.add_parser("build", help="write the Minari dataset of a generated folder and print its size and checksum")
    b.add_argument("out", type=Path)
    b.add_argument("--root", type=Path, default=None, help="Minari's datasets folder (default OUT/minari)")
    q = sub.add_parser("iql", help="train TorchRL's IQL on a built dataset and score it on its noise's track")
    q.add_argument("dataset_dir", type=Path, metavar="DIR", help="the dataset's folder (built)")
    q.add_argument("--updates", type=int, default=20_000, help=f"gradient steps (default 20000, at most {LIMITS['--updates'][1]})")
    q.add_argument("--seed", type=int, default=0, help=f"the learner's seed (0 to {LIMITS['--seed'][1]})")
    q.add_argument("--space", default="raw", choices=SPACES,
                   help="what the learner sees and emits: the env's raw observation and action box (default), or "
                        "aim_features: the carom features and the aim-constrained action, as the project's own agents")
    q.add_argument("--out", type=Path, required=True, help="where iql.json and the scorecard go")
    args = parser.parse_args(argv)
    try:
        return _run(args)
    except OSError as err:  # the file system failed under a checked input (full, gone read-only ...): a sentence too
        raise DatasetError(f"{display_path(err.filename) if err.filename else 'a file'}: {err.strerror or err}") from None


def _run(args) -> int:
    if args.command == "iql":
        rec = train_iql(args.dataset_dir, args.updates, args.out, args.seed, space=args.space)
        print(json.dumps({k: rec[k] for k in ("dataset_id", "updates", "train_cpu_seconds", "track", "success_per_shot")}))
        return 0
    if args.command == "generate":
        generate(args.dataset, args.noise, args.shots, args.out, args.agent, progress=not args.no_progress)
        return 0
    ds = build(args.out, args.root)
    root = Path(args.root or args.out / "minari").resolve()
    size = sum(p.stat().st_size for p in root.rglob("*") if p.is_file())
    rewards = np.stack([ep["rewards"] for ep in episodes(args.out)])
    print(f"{ds.spec.dataset_id}: {ds.total_episodes} episodes, {ds.total_steps} steps, {size / 2**20:.0f} MiB under {root}; "
          f"success per shot {rewards.mean():.2%}, points per inning {rewards.sum(axis=1).mean():.3f}; "
          f"content sha256 {checksum(args.out)}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
