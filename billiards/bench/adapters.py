"""Any agent, adapted once: the one interface every track plays (docs/benchmark.md).

:func:`as_agent` turns what a person names or passes into an :class:`Agent`:

* a plain Python callable on NumPy arrays, ``act(obs) -> action``: it sees the gymnasium env's
  observation (``Billiards4Ball-v0``: 28 floats, plus the shot's noise level where the track
  tells it) and answers in that env's action space, the normalised box [-1, 1]^4 (or the raw
  (theta, p, a, b) with ``normalized=False``); given a batch (B, D) it may answer (B, 4), or,
  written for one table, (4,) (it is then called one table at a time);
* a TorchRL module (``TensorDictModuleBase``: reads ``"observation"``, writes ``"action"``) or a
  plain ``torch.nn.Module`` (observation tensor -> action tensor), same spaces, played under
  ``ExplorationType.DETERMINISTIC``;
* a Stable-Baselines3 model (anything with ``predict``), ``model.predict(obs, deterministic=True)``;
* an :class:`Agent` (kept as it is).

:func:`resolve_agent` reads a spec from the command line:

* ``random``, ``nearest``, ``random_aim``: the reference baselines (uniform in the box; a full-ball
  hit on the nearest red at half power; uniform inside the nearest red's aim window);
* ``path/to/file.py:name`` or ``package.module:name``: that object, through :func:`as_agent`;
* ``sb3:<algo>:<model.zip>``: a saved Stable-Baselines3 model (``sac``, ``td3``, ``ppo``, ...);
* a ``.pt`` file or a training run directory of this project (``results/policies/base/seed0.pt``);
* ``search:<search>[/<proposer>]``: a search of ``search.py`` (``search:h2``, ``search:puct/near_miss``,
  ``search:default``: what ``search.py`` plays under the track's noise; ``search:robust/for_noise``:
  over the shot proposer of the track's noise, ``proposer=for_noise_<preset>``), at the track's budget;
* ``league:<name>``: a player of ``conf/match.yaml`` by name (``league:greedy``, ``league:safety_r``).

The grammar is parsed once (:class:`~billiards.bench.spec.AgentSpec`). Given no name, an agent
built from a spec goes by its :attr:`~billiards.bench.spec.AgentSpec.name` (a file's stem, never its
path). Code is imported only from a spec the person gave or an object they passed; nothing the
benchmark reads from disk (a scorecard, a config, a ledger) names code to import.
"""

from __future__ import annotations

import importlib
import importlib.util
from pathlib import Path

import numpy as np

from billiards import domain

from .spec import BASELINES, AgentError, AgentSpec, SpecKind, spec_name


class Agent:
    """The interface every track plays.

    ``act(obs, tables, levels)``: ``obs`` (B, D) float32, the gymnasium observation of each
    table; ``tables`` (B, 4, 2) float64, the exact tables (the same as the observation's
    positions, at full precision); ``levels`` (B,) float64 or None, the shots' noise levels where
    the track tells them. Returns the raw shots (B, 4) float64 (theta, p, a, b).
    ``reset(seed)`` before every inning block, chain and match (the agent's own randomness).
    ``sims``: simulations used so far (agents that search; 0 for the others): a whole number that
    never goes down, within the track's budget per decision (the evaluation checks both)."""

    kind = "agent"
    compute = "observation"  # or "simulator": searches with the simulator (its budget counted)

    def __init__(self, name: str):
        self.name = name
        self.sims = 0

    def reset(self, seed: int) -> None:
        pass

    def act(self, obs: np.ndarray, tables: np.ndarray, levels: np.ndarray | None) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> dict:
        return {"name": self.name, "kind": self.kind, "compute": self.compute}


_KINDS = {"b": "booleans", "c": "complex numbers", "O": "Python objects", "U": "text", "S": "bytes", "V": "records",
          "M": "dates", "m": "time spans"}


def _element_problem(x) -> str | None:
    """What a single element of an answer is, where it is not a real number."""
    if isinstance(x, (bool, np.bool_)):
        return "booleans"
    if isinstance(x, (complex, np.complexfloating)):
        return "complex numbers"
    if not isinstance(x, (int, float, np.integer, np.floating)):
        return f"{type(x).__name__} objects"
    return None


def checked_action(action, batch: int, name: str) -> np.ndarray:
    """The one check of every answer an agent gives: a (B, 4) float64 array of real, finite
    numbers (or, for one table, (4,)); anything else -- complex numbers (never played as their
    real part), booleans, objects, text, NaN or infinity, another shape -- is an AgentError that
    names the agent and what it returned. Applied to what an adapted callable answers (before its
    normalised action is mapped to a shot) and to the shots every agent returns
    (:class:`billiards.bench.run`'s clock)."""
    def bad(what: str) -> AgentError:
        return AgentError(f"agent {name} returned {what}; an action is 4 real, finite numbers per table")

    if not isinstance(action, np.ndarray):
        if isinstance(action, (list, tuple)):  # a mix hides in a float array: [True, 0.5, 0, 0] -> [1.0, 0.5, 0, 0]
            try:
                items = np.asarray(action, dtype=object).reshape(-1)
            except (TypeError, ValueError):
                items = ()  # ragged: the conversion below says so
            for x in items:
                if not isinstance(x, (list, tuple, np.ndarray)) and (why := _element_problem(x)) is not None:
                    raise bad(why)
        elif not hasattr(action, "__array__") and (why := _element_problem(action)) is not None:
            raise bad(f"{type(action).__name__}, not an array of numbers" if why.endswith("objects") else why)
        try:
            action = np.asarray(action)
        except (TypeError, ValueError, RuntimeError) as err:
            raise bad(f"{type(action).__name__}, not an array of numbers ({err})") from None
    kind = action.dtype.kind
    if kind not in "iuf":
        raise bad(_KINDS.get(kind, f"values of dtype {action.dtype}") + f" (dtype {action.dtype})")
    arr = action.astype(np.float64, copy=False)
    if arr.shape == (domain.ACTION_DIM,) and batch == 1:
        arr = arr[None]
    if arr.shape != (batch, domain.ACTION_DIM):
        raise AgentError(f"agent {name} returned an action of shape {arr.shape}; expected ({batch}, 4) for {batch} "
                         f"tables (or (4,) for one)")
    if not np.isfinite(arr).all():
        raise AgentError(f"agent {name} returned a non-finite action: {arr[~np.isfinite(arr).all(axis=1)][0].tolist()}")
    return arr



def to_raw(action: np.ndarray, name: str, normalized: bool) -> np.ndarray:
    """A checked (B, 4) action in the gymnasium env's space as the raw shot."""
    if not normalized:
        return action
    from billiards.envs._common import unnormalize_checked  # the gymnasium env's own check and map

    try:
        return unnormalize_checked(action)
    except ValueError as err:
        raise AgentError(f"agent {name} answered outside the normalised box: {err} (normalized=False if it answers raw "
                         f"shots)") from None


class CallableAgent(Agent):
    """A NumPy callable ``act(obs) -> action`` (see the module docstring)."""

    kind = "callable"

    def __init__(self, fn, name: str | None = None, normalized: bool = True):
        super().__init__(name or getattr(fn, "__qualname__", None) or type(fn).__name__)
        self.fn, self.normalized = fn, bool(normalized)
        self.one_at_a_time = False
        self.batched = False  # has answered a batch of several tables: a batch function, never probed again

    def _call(self, obs: np.ndarray):
        try:
            return self.fn(obs)
        except AgentError:
            raise
        except Exception as err:
            raise AgentError(f"agent {self.name} raised {type(err).__name__}: {err}") from err

    def _probe_one(self, obs: np.ndarray):
        """The answer for the first table alone where the function is written for one table
        (given one observation (D,) it answers an action (4,)); None where it is not."""
        try:
            out = self.fn(obs[0])
            return out if np.shape(out) == (domain.ACTION_DIM,) else None
        except Exception:
            return None

    def act(self, obs, tables, levels):
        B = obs.shape[0]
        first = None
        if not self.one_at_a_time:
            error, shape = None, None
            try:
                out = self._call(obs)
                shape = np.shape(out)
            except AgentError as err:
                error = err
            except ValueError:  # a ragged answer: checked_action says what is wrong with it
                pass
            if error is None and (shape == (B, domain.ACTION_DIM) or (B == 1 and shape == (domain.ACTION_DIM,))):
                self.batched = self.batched or B > 1
                return to_raw(checked_action(out, B, self.name), self.name, self.normalized)
            # a function written for one table may fail on (or misread) the batch it is first given:
            # asked about the first table alone, it answers (4,)
            first = None if self.batched else self._probe_one(obs)
            if first is None and not (B > 1 and shape == (domain.ACTION_DIM,)):
                if error is not None:
                    raise error
                return to_raw(checked_action(out, B, self.name), self.name, self.normalized)  # says what is wrong
            self.one_at_a_time = True  # written for one table: one call per table from now on
        rows = [checked_action(first if i == 0 and first is not None else self._call(obs[i]), 1, self.name)[0] for i in range(B)]
        return to_raw(np.stack(rows), self.name, self.normalized)

    def describe(self) -> dict:
        return {**super().describe(), "normalized": self.normalized}


def _torch_callable(module):
    """obs (B, D) -> action (B, 4) through a TorchRL module or a plain torch module, deterministic."""
    import torch
    from tensordict import TensorDict
    from tensordict.nn import TensorDictModuleBase
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    is_td = isinstance(module, TensorDictModuleBase)
    try:
        param = next(module.parameters())
        device, dtype = param.device, param.dtype
    except StopIteration:
        device, dtype = torch.device("cpu"), torch.float32

    def act(obs: np.ndarray) -> np.ndarray:
        x = torch.as_tensor(np.asarray(obs), dtype=dtype, device=device)
        batch = x.shape[:-1]
        with set_exploration_type(ExplorationType.DETERMINISTIC), torch.no_grad():
            out = module(TensorDict({"observation": x}, batch_size=batch))["action"] if is_td else module(x)
        return out.detach().cpu().double().numpy()

    return act


class ProjectPolicy(Agent):
    """A policy trained by this project (exported ``.pt`` file or a training run directory): it
    reads the exact table through the domain layers it was trained with (aim constraint, carom
    features, the noise level), as in training."""

    kind = "policy"

    def __init__(self, path: str | Path, params):
        from billiards.files import repo_path
        from billiards.rl.checkpoint import CheckpointError
        from billiards.rl.policy import load_policy, reads_level

        try:
            policy, cfg = load_policy(repo_path(path))
        except (CheckpointError, OSError) as err:
            raise AgentError(f"{path}: not a policy of this project ({err})") from None
        super().__init__(spec_name(str(path)))  # the file's (or the run directory's) stem: never a path of this machine
        self.policy = policy
        self.constrain_aim, self.extra_features = bool(cfg.env.constrain_aim), bool(cfg.env.extra_features)
        self.reads_level, self.R = reads_level(cfg), params.ball_radius
        self.act_fn = _torch_callable(policy)

    def act(self, obs, tables, levels):
        from billiards.envs._common import with_levels

        x = domain.observation(tables, self.extra_features)
        if self.reads_level:
            if levels is None:
                from billiards.rl.policy import level_input_error

                raise AgentError(level_input_error(self.name, "this track tells no level (its noise is not variable)"))
            x = with_levels(x, levels)
        action = checked_action(self.act_fn(x), len(tables), self.name)
        return domain.raw_action(action, tables, self.R, self.constrain_aim)

    def describe(self) -> dict:
        return {**super().describe(), "path": self.name, "constrain_aim": self.constrain_aim,
                "extra_features": self.extra_features}


class RandomAgent(Agent):
    """Uniform in the normalised box (the reference floor)."""

    kind = "baseline"

    def __init__(self):
        super().__init__("random")
        self.rng = np.random.default_rng(0)

    def reset(self, seed):
        self.rng = np.random.default_rng(seed)

    def act(self, obs, tables, levels):
        return domain.unnormalize_action(self.rng.uniform(-1.0, 1.0, (len(tables), domain.ACTION_DIM)))


class NearestRedAgent(Agent):
    """A full-ball hit on the nearest red's centre, half power, centre tip."""

    kind = "baseline"

    def __init__(self, params):
        super().__init__("nearest")
        self.R = params.ball_radius

    def act(self, obs, tables, levels):
        action = np.zeros((len(tables), domain.ACTION_DIM))
        action[:, 0] = domain.aim_window(tables, self.R)[0].reshape(-1)
        action[:, 1] = 0.5
        return action


class RandomAimAgent(Agent):
    """Uniform inside the nearest red's aim window (u, power and tip uniform)."""

    kind = "baseline"

    def __init__(self, params):
        super().__init__("random_aim")
        self.R, self.rng = params.ball_radius, np.random.default_rng(0)

    def reset(self, seed):
        self.rng = np.random.default_rng(seed)

    def act(self, obs, tables, levels):
        x = self.rng.uniform(-1.0, 1.0, (len(tables), domain.ACTION_DIM))
        return domain.raw_action(x, tables, self.R, constrain_aim=True, normalized=True)


class SearchActorAgent(Agent):
    """A search actor of :mod:`billiards.search` (h2, PUCT, the robust and position-aware searches)."""

    kind = "search"
    compute = "simulator"

    def __init__(self, actor, name: str, config: dict | None = None):
        super().__init__(name)
        self.actor, self.config = actor, config or {}

    def reset(self, seed):
        self.actor.reseed(seed)

    def act(self, obs, tables, levels):
        result = self.actor.search(tables) if levels is None else self.actor.search(tables, levels)
        self.sims += int(result.n_sims)
        return np.asarray(result.actions, dtype=np.float64).reshape(len(tables), domain.ACTION_DIM)

    def describe(self) -> dict:
        return {**super().describe(), "config": self.config}


class LeagueAgent(Agent):
    """A player of ``conf/match.yaml`` (:mod:`billiards.league.players`), one table at a time; the
    simulations of its search are counted (its actor's ``search`` wrapped)."""

    kind = "league"

    def __init__(self, name: str, player, config: dict):
        super().__init__(f"league:{name}")
        self.player, self.config = player, config
        self.compute = "observation" if config.get("kind") in ("random", "policy") else "simulator"
        actor = getattr(player, "actor", None)
        if actor is not None:
            search = actor.search

            def counted(*args, **kwargs):
                result = search(*args, **kwargs)
                self.sims += int(result.n_sims)
                return result

            actor.search = counted

    def reset(self, seed):
        self.player.reseed(seed)

    def act(self, obs, tables, levels):
        out = [self.player.act(tables[i]) if levels is None else self.player.act(tables[i], float(levels[i]))
               for i in range(len(tables))]
        return to_raw(checked_action(np.stack(out), len(tables), self.name), self.name, True)

    def describe(self) -> dict:
        return {**super().describe(), "config": self.config}


# ----------------------------------------------------------------------------- adapting objects


def as_agent(obj, name: str | None = None, *, normalized: bool = True) -> Agent:
    """The :class:`Agent` for ``obj`` (see the module docstring), adapted in this one place."""
    if isinstance(obj, Agent):
        return obj
    if hasattr(obj, "predict") and callable(obj.predict):  # Stable-Baselines3 (and look-alikes)
        model = obj
        agent = CallableAgent(lambda obs: model.predict(obs, deterministic=True)[0], name or type(obj).__name__, normalized)
        agent.kind = "sb3"
        return agent
    try:
        import torch

        if isinstance(obj, torch.nn.Module):
            agent = CallableAgent(_torch_callable(obj), name or type(obj).__name__, normalized)
            from tensordict.nn import TensorDictModuleBase

            agent.kind = "torchrl" if isinstance(obj, TensorDictModuleBase) else "torch"
            return agent
    except ImportError:  # pragma: no cover - torch is a dependency
        pass
    if callable(obj):
        return CallableAgent(obj, name, normalized)
    raise AgentError(f"{name or type(obj).__name__} is not an agent: expected a callable obs -> action, a TorchRL or torch "
                     f"module, a Stable-Baselines3 model or a billiards.bench.Agent, got {type(obj).__name__}")


# ----------------------------------------------------------------------------- specs

def _import_object(parsed: AgentSpec):
    """``path/to/file.py:name`` or ``package.module:name`` -> that object (the person's own code)."""
    spec = parsed.text
    target, attr = parsed.target
    if not target or not attr.isidentifier():
        raise AgentError(f"agent {spec!r}: expected file.py:name or package.module:name")
    if target.endswith(".py"):
        path = Path(target)
        if not path.is_file():
            raise AgentError(f"agent {spec!r}: no file {target}")
        mod_name = f"_billiards_agent_{abs(hash(str(path.resolve())))}"
        module_spec = importlib.util.spec_from_file_location(mod_name, path)
        module = importlib.util.module_from_spec(module_spec)
        try:
            module_spec.loader.exec_module(module)
        except Exception as err:
            raise AgentError(f"agent {spec!r}: importing {target} raised {type(err).__name__}: {err}") from err
    else:
        try:
            module = importlib.import_module(target)
        except Exception as err:
            raise AgentError(f"agent {spec!r}: cannot import module {target} ({type(err).__name__}: {err})") from err
    if not hasattr(module, attr):
        raise AgentError(f"agent {spec!r}: {target} has no {attr!r}")
    return getattr(module, attr)


def _sb3(parsed: AgentSpec):
    spec, (algo, path) = parsed.text, parsed.sb3
    try:
        import stable_baselines3 as sb3
    except ImportError:
        from .extras import install_hint

        raise AgentError(f"agent {spec!r}: Stable-Baselines3 is not installed ({install_hint('stable_baselines3')})") from None
    classes = {n.lower(): getattr(sb3, n) for n in ("SAC", "TD3", "PPO", "A2C", "DDPG", "DQN")}
    if algo.lower() not in classes:
        raise AgentError(f"agent {spec!r}: expected sb3:<algo>:<model.zip> with algo one of {', '.join(classes)}")
    if not Path(path).is_file():
        raise AgentError(f"agent {spec!r}: no file {path}")
    try:
        model = classes[algo.lower()].load(path, device="cpu")
    except Exception as err:
        raise AgentError(f"agent {spec!r}: {path} is not a {algo.upper()} model ({type(err).__name__}: {err})") from None
    return as_agent(model, name=f"sb3:{algo.lower()}:{Path(path).stem}")


def _search(parsed: AgentSpec, track) -> Agent:
    """``search:<search>[/<proposer>]``: composed through search.py's own config, for the track."""
    from omegaconf import OmegaConf

    import billiards.search.config as search_config
    from billiards.physics.config import params_from_config
    from billiards.search.run import make_actor, make_proposer

    spec, (search, proposer) = parsed.text, parsed.search
    searches = list(search_config.OPTIONS["search"][1])
    proposers = list(search_config.proposer_options())
    if search not in (*searches, "default"):
        raise AgentError(f"agent {spec!r}: the search must be default or one of {', '.join(searches)}")
    if proposer and proposer not in (*proposers, "ranked", "for_noise"):
        raise AgentError(f"agent {spec!r}: the proposer must be for_noise or one of {', '.join(proposers)}")
    overrides = [f"noise={track.noise}", f"physics={track.physics}", f"search.budget={track.budget}"]
    if search != "default":
        overrides.insert(2, f"search={search}")
    if proposer:  # for_noise: the track's noise's shot proposer (search.py's proposer=for_noise_<preset>)
        overrides.append(f"proposer={proposer}_{track.noise}" if proposer == "for_noise" else f"proposer={proposer}")
    try:
        planned = search_config.compose_search([o for o in overrides if not o.startswith("search.budget=")])
        if planned.search.kind == "h2" and planned.search.budget != track.budget:  # h2's split, scaled to the track's budget
            k1, m1 = search_config.option("search", planned.search).split_for(track.budget)
            overrides += [f"search.k1={k1}", f"search.m1={m1}"]
        cfg = search_config.compose_search(overrides)
    except search_config.SearchConfigError as err:
        raise AgentError(f"agent {spec!r}: {err}") from None
    params = params_from_config(cfg.physics)
    actor = make_actor(cfg, make_proposer(cfg.proposer, params), params)
    record = {"search": OmegaConf.to_container(cfg.search, resolve=True), "proposer": str(cfg.proposer.name)}
    return SearchActorAgent(actor, f"search:{cfg.search.kind}/{cfg.proposer.name}" if search != "default"
                            else f"search:default/{cfg.proposer.name}", record)


def league_players() -> dict:
    """The players of ``conf/match.yaml`` by name (data: their configs)."""
    from omegaconf import OmegaConf

    from billiards.files import ROOT

    return OmegaConf.to_container(OmegaConf.load(ROOT / "conf" / "match.yaml").agents)


def league_player(name: str, noise, params):
    """The league player ``name`` for a match or a track (``noise`` a NoiseModel)."""
    from billiards.league.players import make_agent, player_config

    players = league_players()
    if name not in players:
        raise AgentError(f"no league player {name!r}; players of conf/match.yaml: {', '.join(players)}")
    try:
        cfg = player_config(players[name], name)
    except ValueError as err:
        raise AgentError(str(err)) from None
    errors = cfg.errors(name)
    if errors:
        raise AgentError("; ".join(errors))
    try:
        return make_agent(cfg, noise, params), players[name]
    except ValueError as err:
        raise AgentError(f"league player {name}: {err}") from None


def resolve_agent(spec, track, name: str | None = None) -> Agent:
    """The agent a spec names (see the module docstring), or ``spec`` itself adapted by
    :func:`as_agent` when it is not a string, built for ``track`` (its table, noise, budget)."""
    from billiards.physics import get_params
    from billiards.physics.noise import get_noise

    if not isinstance(spec, (str, Path)):
        return as_agent(spec, name)
    parsed = AgentSpec.parse(spec)
    params = get_params(track.physics)
    if parsed.kind is SpecKind.BASELINE:
        agent = {"random": RandomAgent, "nearest": lambda: NearestRedAgent(params),
                 "random_aim": lambda: RandomAimAgent(params)}[parsed.text]()
    elif parsed.kind is SpecKind.SEARCH:
        agent = _search(parsed, track)
    elif parsed.kind is SpecKind.LEAGUE:
        player, config = league_player(parsed.player, get_noise(track.noise), params)
        agent = LeagueAgent(parsed.player, player, config)
    elif parsed.kind is SpecKind.SB3:
        agent = _sb3(parsed)
    elif parsed.kind is SpecKind.POLICY:
        from billiards.files import repo_path

        if not repo_path(parsed.text).exists():
            raise AgentError(f"agent {parsed.text!r}: no such file or directory")
        agent = ProjectPolicy(parsed.text, params)
    else:
        agent = as_agent(_import_object(parsed), name or parsed.name)
    if name:
        agent.name = name
    return agent


__all__ = ["Agent", "AgentError", "BASELINES", "CallableAgent", "LeagueAgent", "NearestRedAgent", "ProjectPolicy",
           "RandomAgent", "RandomAimAgent", "SearchActorAgent", "as_agent", "checked_action", "league_player", "league_players",
           "resolve_agent", "spec_name", "to_raw"]
