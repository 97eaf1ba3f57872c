"""The benchmark (billiards.bench): every kind of agent adapted and scored on a track, the adapters
agreeing with each other, held-out seeds, track fingerprints, bad agents, the resumable ledger,
``evaluate.py`` and the statistics. Tracks are cut to a few innings / chains / matches."""

import dataclasses
import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from billiards import domain
from billiards.bench import TRACKS, AgentError, EvaluationError, evaluate, get_track, resolve_agent
from billiards.bench.adapters import as_agent
from billiards.bench.run import IDENTITY_FILE, UNITS_FILE, SCORECARD_JSON, SCORECARD_MD, fingerprint
from billiards.physics import get_params, random_racks
from billiards.provenance import cpu

from billiards import stats

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "results" / "policies" / "base" / "seed0.pt"
R = get_params("korean_medium").ball_radius

# tiny tracks: their seeds, noise and physics are the real tracks'
P1 = dataclasses.replace(get_track("p1-exact-v1"), units=4, shots=3, block=2)  # two blocks of two innings
P3 = dataclasses.replace(get_track("p3-exact-v1"), units=2, shots=4)
INNINGS = dataclasses.replace(get_track("innings-v1"), units=2, shots=3)
MATCH = dataclasses.replace(get_track("match-x5-v1"), units=1, opponents=("random",), ratings=(("random", 1000.0),),
                            anchor="random", target=2)


# ----------------------------------------------------------------------------- agents written as a person would


def nearest_act(obs):
    """The nearest-red heuristic as a NumPy callable in the normalised box: a full-ball hit on the
    nearest red (read from the observation), half power (x1 = 0), centre tip. One table or a batch."""
    obs = np.asarray(obs, dtype=np.float64)
    pos = obs[..., :domain.OBS_DIM].reshape(obs.shape[:-1] + (4, 7))[..., :2]
    theta = np.mod(domain.aim_window(pos, R)[0], 2 * np.pi)
    x = np.zeros(obs.shape[:-1] + (4,))
    x[..., 0] = theta / np.pi - 1.0
    return x


def cut_one(o):
    """Written for one table (28,) -> (4,): a cut on red 1 whose side, power and spin depend on the
    table (varied shots: some score, some foul)."""
    dx, dy = float(o[14] - o[0]), float(o[15] - o[1])
    theta = np.arctan2(dy, dx) + 0.12 * np.sign(o[22] - o[8] + 1e-12)
    return np.array([np.mod(theta, 2 * np.pi) / np.pi - 1.0, min(0.9, np.hypot(dx, dy) - 0.3), 0.2, -0.1])


def cut_batch(obs):
    """The same function for a batch (B, 28) -> (B, 4)."""
    return np.stack([cut_one(o) for o in obs])


class Counting:
    """A batch callable that counts its calls and raises on call ``fail_at``."""

    def __init__(self, fn=cut_batch, fail_at=None):
        self.fn, self.fail_at, self.calls = fn, fail_at, 0

    def __call__(self, obs):
        self.calls += 1
        if self.calls == self.fail_at:
            raise RuntimeError("the cue slipped")
        return self.fn(obs)


class LookAlike:
    """An SB3 look-alike: ``predict(obs, deterministic) -> (action, state)``."""

    def __init__(self):
        self.deterministic = []

    def predict(self, obs, deterministic=False):
        self.deterministic.append(deterministic)
        return nearest_act(obs), None


def tiny_torchrl():
    import torch
    from tensordict.nn import TensorDictModule

    torch.manual_seed(0)
    return TensorDictModule(torch.nn.Sequential(torch.nn.Linear(28, 4), torch.nn.Tanh()), in_keys=["observation"],
                            out_keys=["action"])


def tiny_torch():
    import torch

    torch.manual_seed(1)
    return torch.nn.Sequential(torch.nn.Linear(28, 4), torch.nn.Tanh())


def agent_file(tmp_path, body="import numpy as np\n\n\ndef act(obs):\n    return np.zeros((len(obs), 4))\n") -> Path:
    path = tmp_path / "my_agent.py"
    path.write_text(body)
    return path


def ledger(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / UNITS_FILE).read_text().splitlines()]


def outcomes(out: Path) -> list:
    """Every shot's score and foul (innings) or each chain's length and end, from the ledger."""
    return [(r["unit"], r.get("score"), r.get("foul"), r.get("length"), r.get("ended_by_foul")) for r in ledger(out)]


def untimed(out: Path) -> list[dict]:
    """The ledger's records without their timings and seals."""
    return [{k: v for k, v in r.items() if k not in ("cpu_s", "sha256")} for r in ledger(out)]


def files_of(path: Path) -> dict:
    return {p.relative_to(path): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------- 1. every kind of agent, scored


def check_card(card: dict, track) -> None:
    """The keys every scorecard has, and figures that hang together."""
    assert card["track"] == track.name and card["version"] == track.version == 1
    assert isinstance(card["agent"]["name"], str) and card["agent"]["name"]
    assert isinstance(card["ms_per_decision"], float) and card["ms_per_decision"] >= 0
    assert isinstance(card["command"], str) and card["command"] and isinstance(card["commit"], str) and card["commit"]
    assert card["cpu"] == cpu()  # the processor the milliseconds were measured on
    assert card["partial"] is False and card["units_done"] == track.n_blocks()
    if track.protocol in ("innings", "p1"):
        s = card["success_per_shot"]
        lo, hi = s["ci95"]
        assert 0.0 <= lo <= s["mean"] <= hi <= 1.0
        assert s["n_shots"] == track.units * track.shots == card["decisions"] and s["n_innings"] == track.units
        assert len(card["values"]) == track.units
        if track.protocol == "p1":
            assert np.mean(card["values"]) == pytest.approx(s["mean"], abs=1e-6)  # per-inning rates, equal-length innings
        else:
            assert np.mean(card["values"]) == pytest.approx(card["points_per_inning"]["mean"], abs=1e-6)
    elif track.protocol == "p3":
        c = card["chain"]
        assert {"mean", "ci95", "median", "iqm"} <= set(c)
        assert c["ci95"][0] <= c["mean"] <= c["ci95"][1]
        assert len(card["values"]) == track.units and all(0 <= v <= track.shots for v in card["values"])
        assert c["mean"] == pytest.approx(np.mean(card["values"]))
        assert c["median"] == pytest.approx(np.median(card["values"])) and c["iqm"] == pytest.approx(stats.iqm(card["values"]))
        assert 0.0 <= card["success_per_shot"]["mean"] <= 1.0
    else:
        m = card["match"]
        assert m["matches"] == len(track.seeds()) == len(card["values"]) and 0.0 <= m["win_rate"] <= 1.0
        assert 0.0 <= m["ci95"][0] <= m["win_rate"] <= m["ci95"][1] <= 1.0
        ratings = dict(track.ratings)
        assert card["elo"] == stats.elo_against([(ratings[track.opponents[0]], v) for v in card["values"]])


AGENTS = {  # id -> (a factory of the agent or spec given tmp_path, the kind its scorecard records)
    "numpy-batch": (lambda tmp: cut_batch, "callable"),
    "numpy-one-table": (lambda tmp: cut_one, "callable"),
    "torchrl-module": (lambda tmp: tiny_torchrl(), "torchrl"),
    "torch-module": (lambda tmp: tiny_torch(), "torch"),
    "sb3-look-alike": (lambda tmp: LookAlike(), "sb3"),
    "project-policy": (lambda tmp: str(POLICY.relative_to(ROOT)), "policy"),
    "random": (lambda tmp: "random", "baseline"),
    "nearest": (lambda tmp: "nearest", "baseline"),
    "random_aim": (lambda tmp: "random_aim", "baseline"),
    "file-spec": (lambda tmp: f"{agent_file(tmp)}:act", "callable"),
}


@pytest.mark.parametrize("track", [P1, P3, INNINGS], ids=["p1", "p3", "innings"])
@pytest.mark.parametrize("which", list(AGENTS))
@pytest.mark.slow
def test_every_kind_of_agent_is_adapted_and_scored(tmp_path, which, track):
    make, kind = AGENTS[which]
    agent = make(tmp_path)
    card = evaluate(agent, track, progress=False)
    check_card(card, track)
    assert card["agent"]["kind"] == kind and card["agent"]["compute"] == "observation" and card["sims_per_decision"] == 0
    if isinstance(agent, str):
        assert card["agent"]["spec"] == agent
    if isinstance(agent, LookAlike):
        assert agent.deterministic and all(d is True for d in agent.deterministic)


def test_a_scorecard_written_to_a_directory_is_the_one_returned(tmp_path):
    out = tmp_path / "eval"
    card = evaluate(nearest_act, P1, out=out, progress=False, name="near")
    assert json.loads((out / SCORECARD_JSON).read_text()) == json.loads(json.dumps(card))
    md = (out / SCORECARD_MD).read_text()
    assert "# near on p1-exact-v1" in md and "success per shot" in md and card["command"] in md
    assert json.loads((out / IDENTITY_FILE).read_text())["run"] == card["run"]
    assert [r["unit"] for r in ledger(out)] == list(range(P1.n_blocks()))


def test_limit_plays_the_first_units_and_marks_the_scorecard():
    card = evaluate("nearest", "p3-exact-v1", limit=2, progress=False)
    assert card["limit"] == 2 and card["units_done"] == 2 and len(card["values"]) == 2
    assert "limit=2" in card["command"]
    with pytest.raises(ValueError, match="limit must lie in 1..20"):
        evaluate("nearest", "p3-exact-v1", limit=21, progress=False)


@pytest.mark.slow
def test_a_saved_stable_baselines3_model_through_its_spec(tmp_path):
    sb3 = pytest.importorskip("stable_baselines3")
    import gymnasium

    model = sb3.SAC("MlpPolicy", gymnasium.make("Billiards4Ball-v0"), buffer_size=10, learning_starts=0, seed=0, device="cpu")
    path = tmp_path / "sac.zip"
    model.save(path)
    card = evaluate(f"sb3:sac:{path}", P1, progress=False)
    check_card(card, P1)
    assert card["agent"]["kind"] == "sb3" and card["agent"]["name"] == "sb3:sac:sac"  # the model file's stem
    # the loaded model plays what the model itself answers, deterministically
    same = evaluate(lambda obs: model.predict(obs, deterministic=True)[0], P1, progress=False)
    assert same["values"] == card["values"]


def test_a_search_plays_within_the_tracks_budget():
    track = dataclasses.replace(get_track("p1-exact-v1"), units=2, shots=2, block=2)
    card = evaluate("search:h2", track, progress=False)
    check_card(card, track)
    assert card["agent"]["kind"] == "search" and card["agent"]["compute"] == "simulator"
    assert card["agent"]["config"]["search"]["budget"] == track.budget
    assert 0 < card["sims_per_decision"] <= track.budget


@pytest.mark.parametrize("spec", ["league:random", "random"])
def test_a_match_track_against_a_league_player(tmp_path, spec):
    from billiards.bench.adapters import league_players

    assert league_players()["random"]["kind"] == "random"  # conf/match.yaml has the opponent
    card = evaluate(spec, MATCH, out=tmp_path / "m", progress=False)
    check_card(card, MATCH)
    assert card["agent"]["kind"] == ("league" if spec.startswith("league:") else "baseline")
    assert [r["seed"] for r in ledger(tmp_path / "m")] == MATCH.seeds()


# ----------------------------------------------------------------------------- 2. the adapters agree


def test_a_nearest_red_callable_plays_what_the_built_in_nearest_agent_plays(tmp_path):
    racks = random_racks(np.random.default_rng(3), 16)
    obs = domain.observation(racks)
    builtin = resolve_agent("nearest", P1).act(obs, racks, None)
    mine = as_agent(nearest_act).act(obs, racks, None)
    assert np.allclose(np.angle(np.exp(1j * (mine[:, 0] - builtin[:, 0]))), 0.0, atol=1e-5)
    assert np.allclose(mine[:, 1:], builtin[:, 1:])
    # the callable aims from the float32 observation, the built-in agent from the exact tables: their
    # shots differ by ~1e-7 rad, which the table amplifies shot by shot; two-shot innings keep it small
    track = dataclasses.replace(P1, units=8, shots=2, block=4)
    for t, name in ((track, "p1"), (P3, "p3")):
        seen_builtin, seen_mine = [], []
        agent = resolve_agent("nearest", t)
        act = agent.act
        agent.act = lambda obs, tables, levels: seen_builtin.append(tables.copy()) or act(obs, tables, levels)

        def near(obs):
            seen_mine.append(obs[:, :domain.OBS_DIM].reshape(-1, 4, 7)[:, :, :2].copy())
            return nearest_act(obs)

        a = evaluate(agent, t, out=tmp_path / f"builtin-{name}", progress=False)
        b = evaluate(near, t, out=tmp_path / f"callable-{name}", progress=False)
        assert a["values"] == b["values"]
        assert outcomes(tmp_path / f"builtin-{name}") == outcomes(tmp_path / f"callable-{name}")
        # the same tables asked about: the racks to float32 precision, the tables the first shots left to 0.1 mm
        assert len(seen_builtin) == len(seen_mine) == t.n_blocks() * (t.shots if t.protocol == "p1" else 1)
        for i, (x, y) in enumerate(zip(seen_builtin, seen_mine)):
            assert np.allclose(x, y, atol=1e-6 if i % t.shots == 0 or t.protocol == "p3" else 1e-4), i
        if t.protocol == "p1":
            assert np.abs(seen_builtin[0] - seen_builtin[1]).max() > 0.01  # the balls moved between shots


@pytest.mark.parametrize("spec", ["random_aim", "random", "policy"])
def test_the_same_agent_evaluated_twice_gives_the_same_values(spec):
    track = dataclasses.replace(get_track("p1-fastfiz-v1"), units=4, shots=3, block=2)  # noise: its draws replayed too
    agent = resolve_agent(str(POLICY) if spec == "policy" else spec, track)
    first, second = evaluate(agent, track, progress=False), evaluate(agent, track, progress=False)
    assert first["values"] == second["values"] and first["success_per_shot"] == second["success_per_shot"]
    assert first["run"] == second["run"]


def test_a_batch_callable_and_the_same_function_for_one_table_agree(tmp_path):
    for t, name in ((P1, "p1"), (P3, "p3")):
        batch = evaluate(cut_batch, t, out=tmp_path / f"b-{name}", progress=False)
        one = evaluate(cut_one, t, out=tmp_path / f"o-{name}", progress=False)
        assert batch["values"] == one["values"]
        assert outcomes(tmp_path / f"b-{name}") == outcomes(tmp_path / f"o-{name}")
    assert any(np.asarray(r[1]).any() or np.asarray(r[2]).any() for r in outcomes(tmp_path / "b-p1"))  # shots that did something


def test_each_inning_depends_on_its_seed_not_on_the_block_it_is_played_in():
    track = get_track("p1-fastfiz-v1")
    agent = resolve_agent(str(POLICY), track)
    small = evaluate(agent, dataclasses.replace(track, units=4, shots=3, block=1), progress=False)
    large = evaluate(agent, dataclasses.replace(track, units=4, shots=3, block=4), progress=False)
    assert small["units_done"] == 4 and large["units_done"] == 1 and small["values"] == large["values"]


def test_a_track_that_tells_the_level_shows_it_as_the_last_observation_entry():
    seen = []

    def act(obs):
        seen.append(np.array(obs))
        return np.zeros((len(obs), 4))

    evaluate(act, dataclasses.replace(get_track("p1-variable-v1"), units=2, shots=2, block=2), progress=False)
    assert all(o.shape == (2, domain.OBS_DIM + 1) for o in seen)
    assert all(0.0 <= level <= 5.0 for o in seen for level in o[:, -1]) and len({float(o[0, -1]) for o in seen}) > 1
    seen.clear()
    evaluate(act, dataclasses.replace(get_track("p1-x5-v1"), units=2, shots=2, block=2), progress=False)
    assert all(o.shape == (2, domain.OBS_DIM) for o in seen)


# ----------------------------------------------------------------------------- 3. held-out seeds

SEED_KEY = re.compile(r"^seeds?(_\w+)?$|^\w+_seeds?$")
MARGIN = 100_000  # covers P1's seed + i and the leagues' seed + 1000 p + i


def _int(v):
    return isinstance(v, int) and not isinstance(v, bool)


def _collect(node, start, out: list) -> None:
    """(first seed, count) of every seed or run of seeds under a seed-like key: integers, lists of
    them, Hydra sweeps ("0,1,2"), and a count ``seeds: N`` beside (or under) a ``seed``."""
    if isinstance(node, dict):
        own = node.get("seed")
        start = own if _int(own) else start
        for key, value in node.items():
            if isinstance(key, str) and SEED_KEY.match(key):
                if _int(value):
                    out.append((value, 1))
                    if key == "seeds":  # a count of seeds from the run's seed (0 where none is given)
                        out.append((start if _int(start) else 0, value))
                elif isinstance(value, list):
                    out.extend((v, 1) for v in value if _int(v))
                elif isinstance(value, str) and re.fullmatch(r"\s*\d+(\s*,\s*\d+)*\s*", value):
                    out.extend((int(v), 1) for v in value.split(","))
            _collect(value, start, out)
    elif isinstance(node, list):
        for value in node:
            _collect(value, start, out)


def committed_seeds() -> list[tuple[int, int]]:
    out: list = []
    bench_dir = ROOT / "results" / "bench"
    for top in (ROOT / "results", ROOT / "conf"):
        for path in sorted(top.rglob("*")):
            if path.suffix not in (".json", ".jsonl", ".yaml") or bench_dir in path.parents or not path.is_file():
                continue
            if (path.parent / "scorecard.json").is_file():  # a benchmark evaluation elsewhere (an offline baseline's)
                continue
            text = path.read_text()
            if "seed" not in text:
                continue
            if path.suffix == ".json":
                docs = [json.loads(text)]
            elif path.suffix == ".jsonl":
                docs = [json.loads(line) for line in text.splitlines() if line.strip()]
            else:
                docs = list(yaml.load_all(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)))
            for doc in docs:
                _collect(doc, None, out)
    return out


def clashes(track, used: list[tuple[int, int]]) -> list[tuple[int, int, int]]:
    starts = np.array([s for s, _ in used], dtype=np.int64)
    ends = starts + np.array([n for _, n in used], dtype=np.int64) + MARGIN
    seeds = np.array(track.seeds(), dtype=np.int64)
    hit = (seeds[:, None] >= starts[None]) & (seeds[:, None] < ends[None])
    return [(int(seeds[i]), int(starts[j]), int(ends[j] - starts[j] - MARGIN)) for i, j in zip(*np.nonzero(hit))][:5]


@pytest.mark.slow
def test_every_track_seed_is_held_out_from_every_committed_record():
    used = committed_seeds()
    assert len(used) > 1000 and any(n > 1 for _, n in used)  # the walk found the records (and their seed ranges)
    for track in TRACKS.values():
        assert not clashes(track, used), f"{track.name} plays seeds that committed records used: {clashes(track, used)}"
        # the check would see a clash
        assert clashes(track, used + [(track.seeds()[-1] - MARGIN + 1, 1)])
        assert clashes(track, used + [(track.seed - 50, 60)])


def test_the_seed_collector_reads_counts_lists_and_sweeps():
    out: list = []
    _collect({"seed": 40, "protocol": {"name": "p3", "seeds": 10}, "seeds": [1, 2], "sweep": {"seed": "3,4"},
              "eval_seed": 9, "seeds_planned": [5], "note": {"seedling": 7}}, None, out)
    assert sorted(out) == sorted([(40, 1), (10, 1), (40, 10), (1, 1), (2, 1), (3, 1), (4, 1), (9, 1), (5, 1)])


def test_chains_and_matches_play_the_tracks_seeds(tmp_path):
    evaluate("nearest", P3, out=tmp_path / "p3", progress=False)
    assert [r["seed"] for r in ledger(tmp_path / "p3")] == P3.seeds() == [P3.seed, P3.seed + 1]
    two = dataclasses.replace(MATCH, units=2, opponents=("random", "random"))
    assert two.seeds() == [two.seed, two.seed + 1, two.seed + 1000, two.seed + 1001]
    assert P1.seeds() == list(range(P1.seed, P1.seed + P1.units))


# ----------------------------------------------------------------------------- 4. fingerprints


def test_every_tracks_fingerprint_is_recomputed():
    for track in TRACKS.values():
        assert re.fullmatch(r"[0-9a-f]{64}", track.fingerprint)
        assert fingerprint(track) == track.fingerprint, f"{track.name} changed: bump its version"
    assert len({t.fingerprint for t in TRACKS.values()}) == len(TRACKS)


@pytest.mark.parametrize("name", list(TRACKS))
def test_changing_a_track_changes_its_fingerprint(name):
    track = TRACKS[name]
    for change in ({"seed": track.seed + 1}, {"units": track.units - 1}, {"block": track.block + 1}, {"budget": 800},
                   {"shots": track.shots + 1}, {"target": track.target + 1}):
        assert fingerprint(dataclasses.replace(track, **change)) != track.fingerprint, change
    other = "fastfiz" if track.noise == "none" else "none"
    assert fingerprint(dataclasses.replace(track, noise=other, tells_level=False)) != track.fingerprint
    assert fingerprint(dataclasses.replace(track, physics="international")) != track.fingerprint


def test_track_names_versions_and_lookup():
    for name, track in TRACKS.items():
        assert track.name == name and name == f"{track.base}-v{track.version}" and track.protocol in ("innings", "p1", "p3", "match")
        assert track.seeds()[0] == track.seed and len(set(track.seeds())) == len(track.seeds())
    with pytest.raises(ValueError, match="unknown track 'nope'.*p1-exact-v1"):
        get_track("nope")
    with pytest.raises(ValueError, match="limit must lie"):
        get_track("p1-exact-v1").scaled(0)


# ----------------------------------------------------------------------------- 5. bad agents

FAILS_TO_IMPORT = "raise ImportError('needs jax')\n"
BAD_SPECS = {
    "missing file": (lambda tmp: f"{tmp / 'missing.py'}:act", r"no file"),
    "no such attribute": (lambda tmp: f"{agent_file(tmp)}:policy", r"has no 'policy'"),
    "not callable": (lambda tmp: f"{agent_file(tmp, 'act = 3')}:act", r"not an agent.*got int"),
    "no such module": (lambda tmp: "billiards_no_such_module:act", r"cannot import module billiards_no_such_module"),
    "import fails": (lambda tmp: f"{agent_file(tmp, FAILS_TO_IMPORT)}:act", r"importing .* raised ImportError"),
    "names nothing": (lambda tmp: "nearest_red", r"names nothing"),
    "bad search": (lambda tmp: "search:nope", r"the search must be"),
    "no league player": (lambda tmp: "league:nobody", r"no league player 'nobody'"),
    "missing policy": (lambda tmp: f"{tmp / 'gone.pt'}", r"no such file"),
    "bad sb3 algo": (lambda tmp: "sb3:xyz:model.zip", r"algo one of"),
}
NEEDS_SB3 = pytest.mark.skipif(importlib.util.find_spec("stable_baselines3") is None,
                               reason="Stable-Baselines3 is not installed (the sb3 extra): without it an sb3: spec is refused "
                                      "for that, before its algo is read")


@pytest.mark.parametrize("case", [pytest.param(c, marks=NEEDS_SB3) if c.startswith("bad sb3") else c for c in BAD_SPECS])
def test_a_bad_agent_spec_is_refused_before_anything_is_written(tmp_path, case):
    make, message = BAD_SPECS[case]
    out = tmp_path / "x"
    with pytest.raises(AgentError, match=message):
        evaluate(make(tmp_path), P1, out=out, progress=False)
    assert not out.exists()


def test_a_non_callable_object_is_not_an_agent(tmp_path):
    with pytest.raises(AgentError, match="not an agent"):
        evaluate(object(), P1, out=tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()


BAD_ANSWERS = {
    "wrong shape": (lambda obs: np.zeros((len(obs), 3)), r"shape \(2, 3\)"),
    "wrong batch": (lambda obs: np.zeros((len(obs) + 1, 4)), r"shape \(3, 4\)"),
    "nan": (lambda obs: np.full((len(obs), 4), np.nan), r"non-finite"),
    "outside the box": (lambda obs: np.tile([0.0, 2.0, 0.0, 0.0], (len(obs), 1)), r"outside the normalised box"),
    "not numbers": (lambda obs: "shoot", r"not an array of numbers|shape"),
    "raises": (Counting(fail_at=2), r"raised RuntimeError: the cue slipped"),
}


@pytest.mark.parametrize("case", list(BAD_ANSWERS))
def test_an_agent_that_answers_wrongly_stops_the_evaluation_naming_it(case):
    fn, message = BAD_ANSWERS[case]
    if isinstance(fn, Counting):
        fn.calls = 0
    with pytest.raises(EvaluationError, match=message) as err:
        evaluate(fn, P1, name="wobbly", progress=False)
    assert "agent wobbly" in str(err.value) and "p1-exact-v1" in str(err.value)


def test_an_agent_object_that_raises_is_named():
    from billiards.bench import Agent

    class Broken(Agent):
        def act(self, obs, tables, levels):
            raise ZeroDivisionError("no table")

    with pytest.raises(EvaluationError, match=r"agent broken failed on inning block 0 of p1-exact-v1: ZeroDivisionError"):
        evaluate(Broken("broken"), P1, progress=False)


def test_a_failed_evaluation_keeps_its_finished_units_and_resumes_with_the_rest(tmp_path):
    track = dataclasses.replace(P1, units=6, shots=2, block=2)  # 3 units of 2 calls each
    whole = evaluate(cut_batch, track, name="steady", progress=False)
    out = tmp_path / "eval"
    flaky = Counting(fail_at=5)  # the first call of unit 2
    with pytest.raises(EvaluationError, match=r"agent steady raised RuntimeError.*inning block 2.*2 finished units kept"):
        evaluate(flaky, track, out=out, name="steady", progress=False)
    assert [r["unit"] for r in ledger(out)] == [0, 1]
    fixed = Counting()
    card = evaluate(fixed, track, out=out, name="steady", progress=False)
    assert fixed.calls == track.shots  # only the missing unit played
    assert card["values"] == whole["values"] and card["run"] == whole["run"] and card["partial"] is False
    assert [r["unit"] for r in ledger(out)] == [0, 1, 2]
    again = Counting()
    assert evaluate(again, track, out=out, name="steady", progress=False)["values"] == whole["values"] and again.calls == 0


def test_a_failure_mid_unit_loses_only_that_unit(tmp_path):
    track = dataclasses.replace(P1, units=6, shots=2, block=2)
    out = tmp_path / "eval"
    with pytest.raises(EvaluationError):
        evaluate(Counting(fail_at=4), track, out=out, name="steady", progress=False)  # the second shot of unit 1
    assert [r["unit"] for r in ledger(out)] == [0]
    fixed = Counting()
    card = evaluate(fixed, track, out=out, name="steady", progress=False)
    assert fixed.calls == 2 * track.shots and card["values"] == evaluate(cut_batch, track, name="steady", progress=False)["values"]


# ----------------------------------------------------------------------------- 6. the ledger


@pytest.fixture
def finished(tmp_path):
    """A finished evaluation of three units and the scores of the same run kept in memory."""
    track = dataclasses.replace(P1, units=6, shots=2, block=2)
    out = tmp_path / "eval"
    card = evaluate(cut_batch, track, out=out, name="steady", progress=False)
    return track, out, card


def test_a_torn_last_line_is_cut_and_its_unit_played_again(finished):
    track, out, card = finished
    path = out / UNITS_FILE
    data = path.read_bytes()
    last = data.rstrip(b"\n").rfind(b"\n") + 1
    path.write_bytes(data[:last + (len(data) - last) // 2])  # killed halfway through the last append
    agent = Counting()
    again = evaluate(agent, track, out=out, name="steady", progress=False)
    assert agent.calls == track.shots and again["values"] == card["values"]
    assert [r["unit"] for r in ledger(out)] == [0, 1, 2]
    assert path.read_bytes().startswith(data[:last])  # the finished units kept as they were
    assert untimed(out) == [{k: v for k, v in json.loads(line).items() if k not in ("cpu_s", "sha256")}
                            for line in data.decode().splitlines()]  # the torn unit's record written again whole


def test_an_edited_record_is_refused(finished):
    track, out, _ = finished
    path = out / UNITS_FILE
    lines = path.read_text().splitlines()
    rec = json.loads(lines[0])
    rec["score"][0][0] = 1 - rec["score"][0][0]  # the seal kept
    lines[0] = json.dumps(rec, sort_keys=True)
    path.write_text("\n".join(lines) + "\n")
    before = files_of(out)
    with pytest.raises(EvaluationError, match="line 1 is not an intact evaluation unit record: its content does not match its seal"):
        evaluate(Counting(), track, out=out, name="steady", progress=False)
    assert files_of(out) == before


def test_a_record_without_its_seal_or_of_another_run_is_refused(finished, tmp_path):
    track, out, _ = finished
    path = out / UNITS_FILE
    lines = path.read_text().splitlines()
    rec = json.loads(lines[1])
    rec.pop("sha256")
    path.write_text("\n".join([lines[0], json.dumps(rec), lines[2]]) + "\n")
    with pytest.raises(EvaluationError, match="line 2 is not an intact evaluation unit record: it carries no seal"):
        evaluate(Counting(), track, out=out, name="steady", progress=False)
    other = tmp_path / "other"
    evaluate(cut_batch, track, out=other, name="someone else", progress=False)
    path.write_text("\n".join([lines[0], lines[1], (other / UNITS_FILE).read_text().splitlines()[2]]) + "\n")
    with pytest.raises(EvaluationError, match="line 3 belongs to another run"):
        evaluate(Counting(), track, out=out, name="steady", progress=False)


@pytest.mark.parametrize("change", ["agent", "track version", "limit"])
def test_a_directory_of_another_evaluation_is_refused_and_left_as_it_was(finished, change):
    track, out, _ = finished
    before = files_of(out)
    agent, name, kwargs = Counting(), "steady", {}
    if change == "agent":
        name = "someone else"
    elif change == "track version":
        track = dataclasses.replace(track, name="p1-exact-v2")
    else:
        kwargs = {"limit": 2}
    with pytest.raises(EvaluationError, match="holds the evaluation of 'steady'"):
        evaluate(agent, track, out=out, name=name, progress=False, **kwargs)
    assert agent.calls == 0 and files_of(out) == before


def test_a_foreign_directory_is_refused(tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("not an evaluation")
    with pytest.raises(EvaluationError, match="not empty and holds no evaluation"):
        evaluate("nearest", P1, out=out, progress=False)
    assert files_of(out) == {Path("notes.txt"): b"not an evaluation"}
    empty = tmp_path / "empty"
    empty.mkdir()
    evaluate("nearest", P1, out=empty, progress=False)  # an empty directory is fine
    assert (empty / SCORECARD_JSON).is_file()


# ----------------------------------------------------------------------------- 7. the configuration and evaluate.py


def evaluate_config(**overrides):
    from omegaconf import OmegaConf

    from billiards.bench.config import EvaluateConfig

    return OmegaConf.merge(OmegaConf.structured(EvaluateConfig), overrides)


@pytest.mark.parametrize("overrides, message", [
    ({}, "agent=<spec> is required"),
    ({"agent": "nearest", "track": "nope"}, "track='nope' is not a track; tracks: " + ", ".join(TRACKS)),
    ({"agent": "nearest", "limit": 0}, "limit must lie in 1..100 for p1-exact-v1, got 0"),
    ({"agent": "nearest", "track": "p3-exact-v1", "limit": 21}, "limit must lie in 1..20 for p3-exact-v1, got 21"),
    ({"agent": "nearest", "threads": 0}, "threads must lie in 1..256"),
    ({"agent": "nope.py:act"}, "agent 'nope.py:act': no file nope.py"),
    ({"agent": "league:nobody", "track": "match-x5-v1"}, "no league player 'nobody'"),
    ({"agent": "search:nope"}, "the search must be"),
])
def test_config_errors_name_the_problem(overrides, message):
    from billiards.bench.config import errors

    errs = errors(evaluate_config(**overrides))
    assert errs and any(message in e for e in errs), errs


def test_config_errors_check_the_output_directory(tmp_path):
    from billiards.bench.config import errors

    assert errors(evaluate_config(agent="nearest", out=str(tmp_path / "new"))) == []
    (tmp_path / "file").write_text("x")
    assert any("is a file" in e for e in errors(evaluate_config(agent="nearest", out=str(tmp_path / "file"))))
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x.txt").write_text("x")
    assert any("not empty and holds no evaluation" in e for e in errors(evaluate_config(agent="nearest", out=str(tmp_path / "full"))))
    evaluate("nearest", P1, out=tmp_path / "resume", progress=False)
    assert errors(evaluate_config(agent="nearest", out=str(tmp_path / "resume"))) == []  # an evaluation: it continues
    assert not (tmp_path / "new").exists()


def _app(*args, cwd=ROOT):
    """``python evaluate.py <args>``, in this process (conftest.app_here)."""
    from conftest import app_here

    return app_here("evaluate.py", *args, cwd=cwd)


@pytest.mark.slow
def test_evaluate_help_lists_every_track():
    proc = _app("--help")
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name, track in TRACKS.items():
        assert f"  {name}: {track.rules()}" in proc.stdout


@pytest.mark.parametrize("args, message", [
    (["agent=nope.py:act"], "agent 'nope.py:act': no file nope.py"),
    (["track=nope", "agent=nearest"], "track='nope' is not a track"),
], ids=["bad-spec", "bad-track"])
@pytest.mark.slow
def test_evaluate_refuses_a_bad_spec_or_track_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "out"
    proc = _app(*args, f"out={out}")
    assert proc.returncode != 0 and message in proc.stderr + proc.stdout, (proc.stdout, proc.stderr)
    assert not out.exists()


@pytest.mark.slow
def test_evaluate_writes_a_scorecard(tmp_path):
    spec = f"{agent_file(tmp_path)}:act"
    out = tmp_path / "out"
    proc = _app("track=p1-exact-v1", f"agent={spec}", "limit=1", f"out={out}", "progress=false")
    assert proc.returncode == 0, proc.stderr[-2000:]
    card = json.loads((out / SCORECARD_JSON).read_text())
    assert card["track"] == "p1-exact-v1" and card["limit"] == 1 and card["agent"]["spec"] == spec
    assert card["success_per_shot"]["n_shots"] == get_track("p1-exact-v1").shots and card["partial"] is False
    assert card["command"].startswith("python evaluate.py") and f"agent={spec}" in card["command"]
    assert (out / SCORECARD_MD).read_text().startswith("# my_agent:act on p1-exact-v1")  # named by the file's stem, not its path
    here = json.loads(json.dumps(evaluate(spec, "p1-exact-v1", limit=1, progress=False)))
    assert card == here | {k: card[k] for k in ("command", "commit", "ms_per_decision")}  # the app and the library agree


# ----------------------------------------------------------------------------- 8. statistics


def test_bootstrap_ci_contains_the_mean_and_is_deterministic():
    x = np.random.default_rng(0).normal(3.0, 1.0, 40)
    lo, hi = stats.bootstrap_ci(x)
    assert lo < x.mean() < hi and hi - lo < 2.0
    assert stats.bootstrap_ci(x) == [lo, hi]
    assert stats.bootstrap_ci(np.full(5, 0.25)) == [0.25, 0.25] and stats.bootstrap_ci([0.7]) == [0.7, 0.7]
    wide, narrow = stats.bootstrap_ci(x[:10]), stats.bootstrap_ci(np.tile(x, 10))
    assert narrow[1] - narrow[0] < wide[1] - wide[0]


def test_iqm_is_the_mean_of_the_middle_half():
    assert stats.iqm([1, 2, 3, 4, 5, 6, 7, 8]) == pytest.approx(4.5)  # (3 + 4 + 5 + 6) / 4
    assert stats.iqm([8, 0, 0, 1, 1, 1, 1, 100]) == pytest.approx(1.0)
    assert stats.iqm([-1000, 2, 2, 1e9]) == pytest.approx(2.0)


def test_wilson_matches_the_hand_computed_interval():
    z = 1.959963984540054
    n, k = 10, 7
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    assert stats.wilson(7, 10) == pytest.approx([centre - half, centre + half], abs=1e-6)
    assert stats.wilson(7, 10) == pytest.approx([0.3968, 0.8922], abs=1e-4)  # the textbook 7/10 interval
    lo, hi = stats.wilson(0, 20)
    assert lo == 0.0 and 0 < hi < 0.2
    assert stats.wilson(2.5, 5)[0] == pytest.approx(1 - stats.wilson(2.5, 5)[1])  # symmetric at 1/2 (draws count half)


def test_aggregate_is_deterministic_and_its_interval_contains_the_iqm():
    rng = np.random.default_rng(1)
    runs = [rng.normal(m, 1.0, 30) for m in (1.0, 1.5, 2.0)]
    agg = stats.aggregate(runs)
    assert stats.aggregate(runs) == agg
    assert agg["ci95"][0] <= agg["iqm"] <= agg["ci95"][1]
    assert agg["iqm"] == pytest.approx(stats.iqm(np.concatenate(runs)), abs=1e-6) and agg["seeds"] == 3
    assert agg["per_seed"] == pytest.approx([r.mean() for r in runs], abs=1e-6)


def test_probability_of_improvement():
    rng = np.random.default_rng(2)
    better = [rng.normal(3.0, 1.0, 30) for _ in range(3)]
    worse = [rng.normal(0.0, 1.0, 30) for _ in range(3)]
    assert stats.probability_of_improvement(better, worse, resamples=100)["p"] > 0.9
    assert stats.probability_of_improvement(worse, better, resamples=100)["p"] < 0.1
    same = stats.probability_of_improvement(better, better, resamples=100)
    assert same["p"] == pytest.approx(0.5, abs=1e-9) and same["ci95"][0] <= 0.5 <= same["ci95"][1]


def test_elo_against_the_anchor():
    assert stats.elo_against([(1500.0, 0.5)] * 20) == pytest.approx(1500.0, abs=0.1)
    assert stats.elo_against([(1500.0, 1.0), (1500.0, 0.0)] * 10) == pytest.approx(1500.0, abs=0.1)
    elos = [stats.elo_against([(1500.0, 1.0)] * w + [(1500.0, 0.0)] * (20 - w)) for w in (2, 6, 10, 14, 18)]
    assert elos == sorted(elos) and len(set(elos)) == len(elos)
    assert elos[0] < 1500 < elos[-1] and elos[2] == pytest.approx(1500.0, abs=0.1)
    # the expected score at the rating reached equals the score played (with the virtual draw)
    wins = 14
    r = stats.elo_against([(1500.0, 1.0)] * wins + [(1500.0, 0.0)] * (20 - wins))
    assert 1 / (1 + 10 ** ((1500.0 - r) / 400)) == pytest.approx((wins + 0.5) / 21, abs=1e-3)
    assert np.isfinite(stats.elo_against([(1500.0, 1.0)] * 10))  # all won: finite


# ----------------------------------------------------------------------------- registration
# (import billiards in a fresh interpreter: tests/test_fresh_interpreter.py)


# ----------------------------------------------------------------------------- the leaderboard


def _board_root(tmp_path):
    """A results/bench-like root: two played scorecards on p3-exact-v1 (random, nearest: fast) and a submission."""
    from billiards.bench.run import evaluate as play

    root = tmp_path / "bench"
    for name in ("random", "nearest"):
        play(name, "p3-exact-v1", out=root / "scorecards" / "p3-exact-v1" / name, progress=False, group=f"{name} row")
    play("random_aim", "p3-exact-v1", out=root / "submissions" / "p3-exact-v1" / "theirs", progress=False, group="their agent")
    return root


def test_the_leaderboard_pools_ranks_and_marks_submissions(tmp_path):
    from billiards.bench.leaderboard import build

    root = _board_root(tmp_path)
    paths = build(root, tmp_path / "out", figure=False)
    board = json.loads(paths[0].read_text())
    rows = board["tracks"]["p3-exact-v1"]["rows"]
    assert {r["row"] for r in rows} == {"random row", "nearest row", "their agent"}
    assert [r["score"] for r in rows] == sorted((r["score"] for r in rows), reverse=True)
    assert {r["row"]: r["status"] for r in rows}["their agent"] == "unverified"
    assert all(r["ci95"][0] <= r["score"] <= r["ci95"][1] for r in rows)
    assert "p_above_next" in rows[0] and "profiles" in board["tracks"]["p3-exact-v1"]
    again = build(root, tmp_path / "again", figure=False)
    assert [p.read_bytes() for p in paths] == [p.read_bytes() for p in again]  # byte for byte
    assert "## p3-exact-v1" in paths[1].read_text() and "their agent" in paths[1].read_text()


def test_the_leaderboard_refuses_a_scorecard_its_ledger_does_not_give(tmp_path):
    from billiards.bench.leaderboard import build

    root = _board_root(tmp_path)
    card_path = root / "scorecards" / "p3-exact-v1" / "random" / SCORECARD_JSON
    card = json.loads(card_path.read_text())
    card["values"] = [card["track_record"]["shots"]] * len(card["values"])  # a forged scorecard: every chain at the cap
    card_path.write_text(json.dumps(card))
    with pytest.raises(ValueError, match=r"its values \(\[1000, 1000.*\) differs from what its ledger gives \(\[0, 0"):
        build(root, tmp_path / "out", figure=False)
    card["version"] = 0
    card_path.write_text(json.dumps(card))
    with pytest.raises(ValueError, match="play it again on the current version"):
        build(root, tmp_path / "out", figure=False)


@pytest.mark.slow
def test_the_committed_leaderboard_regenerates_byte_for_byte(tmp_path):
    committed = ROOT / "results" / "leaderboard.json"
    if not committed.is_file():
        pytest.skip("no committed leaderboard")
    from conftest import app_here

    proc = app_here("billiards.bench", "leaderboard", "--out", str(tmp_path), "--no-figure", cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    for name in ("leaderboard.json", "leaderboard.md"):
        assert (tmp_path / name).read_bytes() == (ROOT / "results" / name).read_bytes(), name
    board = json.loads(committed.read_text())
    assert board["agents"] >= 15


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_two_scorecards_of_one_track_are_compared_unit_by_unit(tmp_path):
    """python -m billiards.bench compare: the paired difference of the per-unit scores (per shot
    on an innings track), its bootstrap interval and the units each is ahead on; a scorecard of
    another track, or of fewer units, is refused with its reason."""
    from billiards.bench.leaderboard import compare

    mine = ROOT / "results/bench/scorecards/innings-v1/sac_base_s0"
    card = json.loads((mine / SCORECARD_JSON).read_text())
    better = dict(card, values=[min(v + 1, 10) for v in card["values"]], agent=dict(card["agent"], name="better"))
    (tmp_path / "better.json").write_text(json.dumps(better))
    c = compare(tmp_path / "better.json", mine)
    gain = np.mean(np.minimum(np.asarray(card["values"]) + 1, 10) - card["values"]) / 10
    assert c["unit"] == "success per shot" and c["first"] == "better" and c["second"] == "sac_base_s0"
    assert c["difference"] == pytest.approx(gain) and c["ci95"][0] <= c["difference"] <= c["ci95"][1] <= 0.1
    assert c["first_mean"] == pytest.approx(card["success_per_shot"]["mean"] + gain)
    assert c["first_better"] == sum(v < 10 for v in card["values"]) and c["second_better"] == 0
    assert compare(mine, tmp_path / "better.json")["difference"] == pytest.approx(-gain)

    (tmp_path / "short.json").write_text(json.dumps(dict(card, values=card["values"][:-1])))
    with pytest.raises(ValueError, match="has 100 units"):
        compare(mine, tmp_path / "short.json")
    other = ROOT / "results/bench/scorecards/p1-exact-v1/sac_base_s0"
    with pytest.raises(ValueError, match="is on innings-v1"):
        compare(mine, other)
    from conftest import app_here

    out = app_here("billiards.bench", "compare", str(tmp_path / "better.json"), str(mine), cwd=ROOT)
    assert out.returncode == 0 and "paired 95 % interval" in out.stdout and f"{100 * gain:+.2f} points" in out.stdout
    bad = app_here("billiards.bench", "compare", str(mine), str(other), cwd=ROOT)
    assert bad.returncode == 1 and "Error:" in bad.stderr and "compare one track" in bad.stderr
