"""Reading what earlier versions wrote, in one place.

Every kind of file the package saves and reads back has one *upgrade chain* here: the steps
that turn each older form into the next, oldest first (:class:`Chain`, :class:`Step`), and
one function that runs them (``upgrade_<kind>``). A reader elsewhere calls that function and
then reads today's form only: nothing else in the package knows an old form
(``tests/test_compat.py`` builds each older form from a file of today and greps the package
for the others).

Schema versions. A file that carries its form's version under :data:`SCHEMA_KEY` (``"schema"``)
starts its chain after that version, and one of a version newer than this code reads is
refused; a file without one is of the oldest form, version 0. Training checkpoints carry it
(they are never committed). Configs, evaluation records, ledgers and model files carry none:
a version key there would change the run identities and the bytes of committed results. Their
chains run every step, so each step only adds what a file lacks (or drops what it no longer
may hold): on today's form every step is a no-op.

Keys a schema gained with a default that reproduces what runs did before the key existed need
no step: a saved config merged into its schema takes that default (the training and search
apps merge, and :func:`billiards.rl.checkpoint.agent_from_config` merges the algorithm's
node). A step is here where that default is not what the older runs did (the physics), or where
a reader reads the file without its schema.

The kinds and their steps:

* training configs (a run's ``config.yaml``, a checkpoint's and an exported policy's
  ``config``; :data:`TRAINING_CONFIG`, :func:`upgrade_training_config`):

  1. ``physics``: a config saved before the physics presets has no ``physics`` node; it played
     pooltool's international table (:data:`LEGACY_PHYSICS`);
  2. ``noise``: one saved before execution noise has no ``noise`` node; it played exact shots;
  3. ``noise.scale``: a noise node saved before ``noise.scale`` and variable noise has neither
     ``scale`` (1: the preset's sigmas) nor ``level_range`` (null: the preset's);
  4. retired keys (:data:`RETIRED_KEYS`) are dropped: nothing reads them any more.

* search configs (a search run's ``config.yaml``; :func:`upgrade_search_config`): the union
  nodes (each group's node held every option's keys, :data:`LEGACY_UNION_KEYS`; today each
  option has its own closed schema), then the training configs' ``physics``, ``noise`` and
  ``noise.scale`` steps.

* league records (a league's ``league.json``; :func:`upgrade_league_players`): each player's
  node held every kind's keys (:data:`LEGACY_PLAYER_KEYS`, one schema for every kind); today
  each kind has its own closed schema, and the other kinds' keys are dropped.

* training checkpoints (format 2; :data:`CHECKPOINT`, :func:`upgrade_checkpoint`; version 1
  from the first that carries :data:`SCHEMA_KEY`). Format 1, before the checksum, was a plain
  ``torch.save`` pickle holding numpy objects: it is refused, since loading it would need the
  unsafe unpickler (:func:`checkpoint_format_refusal`).

  1. ``collector``: a checkpoint written before the collector's state was saved holds no
     ``collector`` (None: the resumed run's collector starts fresh innings) and no
     ``rng.env_noise`` (None: the execution-noise generator keeps its seeded state, as the
     version that wrote it did); ``stage_log`` and ``eval_history`` (empty), ``wandb_id`` and
     ``buffer`` (None) are added where absent too.

  Its ``config`` is a training config (above) whatever the checkpoint's version.

* exported policy files (``billiards-policy-1``; :func:`upgrade_policy_file`): the ``config``
  is a training config and the ``eval`` an evaluation record.

* evaluation records (``eval.json``, a policy file's ``eval``; :data:`EVAL_RECORD`,
  :func:`upgrade_eval_record`):

  1. ``noise``: a record written before execution noise names none (``"none"``);
  2. ``first_miss_points``: one written before the points to the first miss were recorded
     has none (an empty list: not recorded).

* artefact metadata (a reward-model data set's ``meta.json``, a reward model's ``meta``;
  :data:`ARTEFACT_META`, :func:`upgrade_artefact_meta`):

  1. ``physics``: one saved before the presets records no ``physics_params``; it was made on
     the international table.

* ledgers (a P3's ``chains.jsonl``, a league's ``matches.jsonl``; :func:`ledger_scan`,
  :func:`ledger_records`): records written before ledgers were sealed carry no seal (form 0)
  or a seal but no run identity (form 1). Read-only views read them on their shape
  (:func:`billiards.files.scan_ledger` with ``unchecked``); a resume reads today's form only
  (sealed, with the run's identity) and refuses them.

* tagged model files (exported policies, shot rankers, table values, reward models): one
  written before files were sealed carries no checksum; the loaders refuse it, and
  ``python -m billiards.compat seal FILE`` (:func:`seal`) checks its content and seals it.

The committed results were migrated once where their bytes could change (every committed
training config and search result names its table and row, or its physics); the committed
ledgers, evaluation records and policy files are read through the chains above.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable


SCHEMA_KEY = "schema"  # the version of a file's form, in the files that carry one
LEGACY_PHYSICS = "international"  # the table of files saved before the physics presets existed
RETIRED_KEYS = ("budget.kill_after_checkpoint",)
LEGACY_UNION_KEYS = {
    "search": ("k1", "m1", "c_puct", "pw_c", "pw_alpha", "pool", "max_depth",
               "samples", "schedule", "screen", "quantile", "k2", "target", "wave", "antithetic"),
    "protocol": ("n_innings", "shots", "seeds", "cap"),
    "proposer": ("checkpoints", "command", "power_low", "power_high", "u_low", "u_high", "spin_low", "spin_high"),
}
# A league player's keys when every kind shared one schema: a league.json of then holds them all
# for every player (today each kind has its own closed schema, billiards.league.players.PLAYERS)
LEGACY_PLAYER_KEYS = ("search", "proposer", "search_budget", "k", "replays", "opp_k", "opp_replays", "foul_penalty",
                      "leave_weight", "threshold", "overrides", "policy")
# The noise node as it was when the node was added, before noise.scale and variable noise
_FIRST_NOISE_NODE = {"preset": "none", "aim_deg": None, "speed": None, "tip_mm": None}


class NewerFormError(ValueError):
    """A file of a newer form than this version of billiards reads."""


@dataclass(frozen=True)
class Step:
    """One step of a chain: ``apply`` turns a file of the form before ``version`` into that form.

    ``added``: the dotted keys the older form lacks and the step adds; ``dropped``: the keys the
    older form may hold and the step drops (what ``tests/test_compat.py`` takes away from, or
    adds to, a file of today to build the older form)."""

    version: int
    name: str
    what: str  # what the older form lacked, in words
    apply: Callable[[dict], dict]
    added: tuple[str, ...] = ()
    dropped: tuple[str, ...] = ()


@dataclass(frozen=True)
class Chain:
    """The upgrade chain of one kind of file: its steps, oldest first; ``versioned``: whether
    today's files of the kind carry their version under :data:`SCHEMA_KEY`."""

    kind: str
    steps: tuple[Step, ...]
    versioned: bool = False

    @property
    def version(self) -> int:
        """Today's version of the kind's form."""
        return self.steps[-1].version if self.steps else 0

    def upgrade(self, data: Any) -> Any:
        """``data`` (a plain dict, not changed) in today's form: every step after the version it
        carries (none, or a kind without versions: every step). Anything but a dict is returned
        as it is, for the reader's own checks to refuse. :class:`NewerFormError` for a file of a
        newer version than this code reads."""
        if not isinstance(data, dict):
            return data
        start = data.get(SCHEMA_KEY, 0) if self.versioned else 0
        if isinstance(start, bool) or not isinstance(start, int) or start < 0:
            raise NewerFormError(f"its {SCHEMA_KEY}={start!r} is not a version of a {self.kind}")
        if start > self.version:
            raise NewerFormError(f"it is a {self.kind} of version {start}, written by a newer version of billiards; "
                                 f"this one reads versions up to {self.version}")
        out = data
        for step in self.steps:
            if step.version > start:
                out = step.apply(out)
        if self.versioned:
            out = {**out, SCHEMA_KEY: self.version}
        return out


# ----------------------------------------------------------------------------- helpers


def _node(d: dict, path: str) -> Any:
    """The value at a dotted path of nested dicts, or None."""
    for key in path.split("."):
        d = d.get(key) if isinstance(d, dict) else None
    return d


def _without(d: dict, path: list[str]) -> dict:
    head, *rest = path
    return {k: (_without(v, rest) if k == head and rest and isinstance(v, dict) else v)
            for k, v in d.items() if rest or k != head}


def _with_default(container: dict, key: str, value: Any) -> dict:
    """A copy of ``container`` with ``key`` set to a copy of ``value`` where absent (itself otherwise)."""
    return container if key in container else {**container, key: copy.deepcopy(value)}


# ----------------------------------------------------------------------------- configs


def with_physics(container: dict) -> dict:
    """A saved config with its ``physics`` node (``international``, no overrides, for one saved
    before the presets)."""
    if container.get("physics") is not None:
        return container
    from billiards.physics.params import PhysicsParams  # here: loading compat must not load the simulator

    node = {"preset": LEGACY_PHYSICS, **{f.name: None for f in dataclasses.fields(PhysicsParams)}}
    return {**container, "physics": node}


def with_noise(container: dict) -> dict:
    """A saved config with its ``noise`` node (exact play for one saved before execution noise)."""
    return container if container.get("noise") is not None else {**container, "noise": dict(_FIRST_NOISE_NODE)}


def with_noise_scale(container: dict) -> dict:
    """A saved config whose noise node has ``scale`` (1) and ``level_range`` (null) where absent."""
    node = container.get("noise")
    if not isinstance(node, dict) or ("scale" in node and "level_range" in node):
        return container
    return {**container, "noise": {**node, "scale": node.get("scale", 1.0), "level_range": node.get("level_range")}}


def without_retired(container: dict) -> dict:
    """A saved config without the :data:`RETIRED_KEYS` (a copy where it had any)."""
    out = container
    for key in RETIRED_KEYS:
        *parents, leaf = key.split(".")
        node = _node(out, ".".join(parents)) if parents else out
        if isinstance(node, dict) and leaf in node:
            out = _without(out, key.split("."))
    return out


_PHYSICS = Step(1, "physics", "no physics node: saved before the physics presets, played on the international table",
                with_physics, added=("physics",))
_NOISE = Step(2, "noise", "no noise node: saved before execution noise, played exact shots", with_noise, added=("noise",))
_NOISE_SCALE = Step(3, "noise.scale", "a noise node without scale and level_range: saved before noise.scale and "
                    "variable noise", with_noise_scale, added=("noise.scale", "noise.level_range"))
TRAINING_CONFIG = Chain("training config", (
    _PHYSICS, _NOISE, _NOISE_SCALE,
    Step(4, "retired keys", "keys the schema no longer has", without_retired, dropped=RETIRED_KEYS),
))


def upgrade_training_config(container: Any) -> Any:
    """A saved training config (a plain dict) in today's form (:data:`TRAINING_CONFIG`)."""
    return TRAINING_CONFIG.upgrade(container)




SEARCH_CONFIG = Chain("search config", (_PHYSICS, _NOISE, _NOISE_SCALE))  # after the union nodes' step


def upgrade_search_config(saved: dict, own_keys: Callable[[str, dict], set]) -> dict:
    """A saved search config (a plain dict) in today's form: the other options' keys of the old
    union nodes dropped (``own_keys(group, node)``: the keys of the node's option schema), and
    the ``physics``, ``noise`` and ``noise.scale`` steps of :data:`TRAINING_CONFIG`."""
    out = dict(saved)
    for group, legacy in LEGACY_UNION_KEYS.items():
        node = out.get(group)
        if isinstance(node, dict):
            own = own_keys(group, node)
            out[group] = {k: v for k, v in node.items() if k in own or k not in legacy}
    return SEARCH_CONFIG.upgrade(out)




def upgrade_league_players(agents: Any, own_keys: Callable[[str], set]) -> Any:
    """A league.json's ``agents`` (name -> player node) in today's form: the keys of the one
    player schema every kind shared that the player's own kind does not take are dropped
    (``own_keys(kind)``: the keys of that kind's schema; they never changed how it played)."""
    if not isinstance(agents, dict):
        return agents
    return {name: {k: v for k, v in node.items() if k in own_keys(node.get("kind", "search")) or k not in LEGACY_PLAYER_KEYS}
            if isinstance(node, dict) else node for name, node in agents.items()}


def upgrade_config_nodes(saved: Any) -> Any:
    """The ``physics`` and ``noise`` nodes of a saved config of either app (training or search)
    in today's form (the ``physics``, ``noise`` and ``noise.scale`` steps), for a reader that
    needs only those (the viewer's run list)."""
    return SEARCH_CONFIG.upgrade(saved)


# ----------------------------------------------------------------------------- checkpoints


def _checkpoint_v1(state: dict) -> dict:
    out = dict(state)
    for key, value in (("collector", None), ("stage_log", []), ("eval_history", []), ("wandb_id", None), ("buffer", None)):
        out = _with_default(out, key, value)
    if isinstance(out.get("rng"), dict) and "env" in out["rng"]:
        out["rng"] = _with_default(out["rng"], "env_noise", None)
    return out


CHECKPOINT = Chain("training checkpoint", (
    Step(1, "collector", "no collector state and no execution-noise generator state (and, in its first versions, "
         "no stage log, evaluation history, wandb id or buffer entry)", _checkpoint_v1,
         added=("collector", "rng.env_noise", "stage_log", "eval_history", "wandb_id", "buffer")),
), versioned=True)


_FORMAT_1 = b"PK\x03\x04"  # what a format-1 checkpoint (a bare torch.save, a zip archive) starts with


def checkpoint_format_refusal(head: bytes) -> str | None:
    """Why a checkpoint file that starts with ``head`` is of a format this version never reads
    (format 1), or None."""
    if head.startswith(_FORMAT_1):
        return ("was written by an older version of billiards in an unsafe format (checkpoint format 1, a pickle "
                "that can run code when loaded)")
    return None


def upgrade_checkpoint(state: Any) -> Any:
    """A loaded training checkpoint (format 2) in today's form (:data:`CHECKPOINT`), its config
    too (:data:`TRAINING_CONFIG`). :class:`NewerFormError` for one of a newer version."""
    out = CHECKPOINT.upgrade(state)
    if isinstance(out, dict) and isinstance(out.get("config"), dict):
        out = {**out, "config": upgrade_training_config(out["config"])}
    return out


# ----------------------------------------------------------------------------- results


EVAL_RECORD = Chain("evaluation record", (
    Step(1, "noise", "no noise: written before execution noise (exact play)",
         lambda r: _with_default(r, "noise", "none"), added=("noise",)),
    Step(2, "first_miss_points", "no points to the first miss: written before they were recorded (not recorded)",
         lambda r: _with_default(r, "first_miss_points", []), added=("first_miss_points",)),
))


def upgrade_eval_record(record: Any) -> Any:
    """An evaluation record (``eval.json``) in today's form (:data:`EVAL_RECORD`)."""
    return EVAL_RECORD.upgrade(record)


def upgrade_scorecard(card: dict) -> dict:
    """A scorecard in today's form: older scorecards claimed a status (``"verified": true``);
    today the folder a scorecard lies in gives it (billiards.bench.leaderboard), so the claim is dropped."""
    return {k: v for k, v in card.items() if k != "verified"}


def upgrade_policy_file(payload: Any) -> Any:
    """An exported policy file's payload in today's form: its ``config`` a training config of
    today's form, its ``eval`` (if any) an evaluation record of today's form."""
    if not isinstance(payload, dict):
        return payload
    out = dict(payload)
    if isinstance(out.get("config"), dict):
        out["config"] = upgrade_training_config(out["config"])
    if isinstance(out.get("eval"), dict):
        out["eval"] = upgrade_eval_record(out["eval"])
    return out


def _artefact_physics(meta: dict) -> dict:
    if meta.get("physics_params"):
        return meta
    from billiards.physics.params import PRESETS

    return {**meta, "physics": LEGACY_PHYSICS, "physics_params": PRESETS[LEGACY_PHYSICS].to_dict()}


ARTEFACT_META = Chain("artefact's metadata", (
    Step(1, "physics", "no physics_params: saved before the physics presets, made on the international table",
         _artefact_physics, added=("physics_params",)),
))


def upgrade_artefact_meta(meta: Any) -> Any:
    """A data set's or a reward model's metadata in today's form (:data:`ARTEFACT_META`)."""
    return ARTEFACT_META.upgrade(meta)


CHAINS = {chain.kind: chain for chain in (TRAINING_CONFIG, SEARCH_CONFIG, CHECKPOINT, EVAL_RECORD, ARTEFACT_META)}


# ----------------------------------------------------------------------------- ledgers


def ledger_scan(data: bytes, name: str, kind):
    """A ledger's bytes read for a read-only view (``name``: the file, for the messages): the
    records of today's form and those written before ledgers were sealed (no seal, or a seal
    without the run's identity), these on their shape alone and listed in the scan's
    ``unchecked`` (:func:`billiards.files.scan_ledger`)."""
    from billiards.files import scan_ledger

    return scan_ledger(data, name, kind, unchecked=True)


def ledger_records(path, kind) -> list[dict]:
    """The records of the ledger at ``path`` for a read-only view (none if there is no file):
    today's form and the forms written before ledgers were sealed (:func:`ledger_scan`);
    :class:`billiards.files.LedgerError` naming the file and the first bad line otherwise. A
    resume never reads a ledger this way: it reads today's form only."""
    from billiards.files import read_ledger

    return read_ledger(path, kind, unchecked=True).records


# ----------------------------------------------------------------------------- tagged files


def seal(path) -> str:
    """Add the checksum to a tagged file written before files were sealed, after checking that
    it loads as tensors and plain values and holds only finite numbers; returns the digest."""
    import torch

    from billiards.files import SEAL_KEY, non_finite_entry, payload_digest, save_tagged

    payload = torch.load(Path(path), map_location="cpu", weights_only=True)
    if not isinstance(payload, dict) or not isinstance(payload.get("format"), str):
        raise ValueError(f"{path} is not a tagged file (no format entry)")
    if (bad := non_finite_entry(payload)) is not None:
        raise ValueError(f"{path} holds non-finite values (NaN or inf) in {bad}: not sealed")
    payload.pop(SEAL_KEY, None)
    save_tagged(path, payload)
    return payload_digest(payload)


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m billiards.compat", description="Bring files an earlier version "
                                 "wrote to today's form.")
    sub = ap.add_subparsers(dest="command", required=True)
    sp = sub.add_parser("seal", help="seal each tagged file (policies, rankers, table values, reward models) written "
                                     "before checksums, in place, after checking its content")
    sp.add_argument("paths", nargs="+", type=Path)
    args = ap.parse_args(argv)
    for p in args.paths:
        try:
            print(f"{p}: sealed, sha256 {seal(p)[:16]}...")
        except (OSError, ValueError, RuntimeError) as err:
            print(f"Error: {p}: {err}")
            return 2
    return 0


__all__ = ["ARTEFACT_META", "CHAINS", "CHECKPOINT", "Chain", "EVAL_RECORD", "LEGACY_PHYSICS", "LEGACY_UNION_KEYS",
           "NewerFormError", "RETIRED_KEYS", "SCHEMA_KEY", "SEARCH_CONFIG", "Step", "TRAINING_CONFIG",
           "checkpoint_format_refusal", "ledger_records", "ledger_scan", "main", "seal",
           "upgrade_artefact_meta", "upgrade_checkpoint", "upgrade_config_nodes", "upgrade_eval_record", "upgrade_policy_file",
           "upgrade_scorecard", "upgrade_search_config", "upgrade_training_config", "with_noise", "with_noise_scale", "with_physics",
           "without_retired"]


if __name__ == "__main__":
    raise SystemExit(main())
