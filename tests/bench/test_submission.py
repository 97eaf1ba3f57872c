"""Submitting to the leaderboard (docs/benchmark.md, "Submitting an agent"): an agent's name is
never a path, a scorecard claims no status, the rebuild says what it leaves out and where it
found nothing, the board counts outside rows apart, a score's placement on the committed
board, and a failure that is not the agent's is not put on it."""

from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from billiards.bench import Agent, AgentError, EvaluationError, evaluate, get_track
from billiards.bench.run import SCORECARD_JSON

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "results" / "policies" / "base" / "seed0.pt"
SNAPSHOT = ROOT / "results" / "leaderboard.json"
P1 = dataclasses.replace(get_track("p1-exact-v1"), units=2, shots=2, block=2)
P3 = "p3-exact-v1"  # a whole track that the baselines play in a fraction of a second (their chains end at once)


def zeros(obs):
    return np.zeros((len(obs), 4))


def agent_file(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "my_agent.py"
    path.write_text("import numpy as np\n\n\ndef act(obs):\n    return np.zeros((len(obs), 4))\n")
    return path


def bench_cli(*args: str, cwd: Path = ROOT):
    """``python -m billiards.bench <args>``, in this process (conftest.app_here)."""
    from conftest import app_here

    return app_here("billiards.bench", *args, cwd=cwd)


@pytest.fixture(scope="module")
def played(tmp_path_factory) -> Path:
    """A results/bench-like folder: two project rows on p3-exact-v1 and one outside submission."""
    root = tmp_path_factory.mktemp("played") / "bench"
    for name in ("random", "nearest"):
        evaluate(name, P3, out=root / "scorecards" / P3 / name, progress=False, group=f"{name} row")
    evaluate("random_aim", P3, out=root / "submissions" / P3 / "theirs", progress=False, name="their-agent")
    return root


@pytest.fixture
def board_root(played, tmp_path) -> Path:
    """A copy of :func:`played` this test may change."""
    return Path(shutil.copytree(played, tmp_path / "bench"))


def build_board(root: Path, out: Path, report=None) -> tuple[dict, str]:
    from billiards.bench.leaderboard import build

    paths = build(root, out, figure=False, report=report)
    return json.loads(paths[0].read_text()), paths[1].read_text()


# ----------------------------------------------------------------------------- 1. names are never paths


@pytest.mark.parametrize("spec, name", [
    ("agents/mine.py:act", "mine:act"),
    ("/srv/someone/agents/mine.py:policy", "mine:policy"),
    ("mine.py:act", "mine:act"),
    ("results/policies/base/seed0.pt", "seed0"),
    ("/data/runs/outputs/2026-11-26/10-00-00_sac/", "10-00-00_sac"),
    ("C:\\runs\\seed1.pt", "seed1"),
    ("package.module:act", "package.module:act"),
    ("search:h2/geometric", "search:h2/geometric"),
    ("random", "random"),
])
def test_a_spec_gives_a_name_that_is_never_a_path(spec, name):
    from billiards.bench.adapters import spec_name
    from billiards.bench.leaderboard import looks_like_path

    assert spec_name(spec) == name
    assert not looks_like_path(spec_name(spec))


@pytest.mark.parametrize("name", ["/srv/me/agents/mine.py:act", "agents/mine.py:act", "mine.py:act", "runs/base/seed0.pt",
                                  "seed0.pt", "~/agents/mine", "./mine", "..\\mine", "C:\\agents\\mine.py:act", "dir/my agent"])
def test_a_name_that_names_a_file_looks_like_a_path(name):
    from billiards.bench.leaderboard import looks_like_path

    assert looks_like_path(name)


def test_no_committed_scorecard_is_named_after_a_path():
    from billiards.bench.leaderboard import looks_like_path

    bench = ROOT / "results" / "bench"
    cards = sorted(bench.glob("*/*/*/scorecard.json")) + sorted(bench.glob("recorded/*/*.json"))
    assert len(cards) > 100
    for path in cards:
        agent = json.loads(path.read_text())["agent"]
        assert not looks_like_path(agent["name"]), path
        assert not looks_like_path(agent.get("group") or "x"), path


def test_an_agent_given_no_name_is_named_from_its_spec_not_its_path(tmp_path):
    spec = f"{agent_file(tmp_path / 'deep' / 'folder')}:act"
    card = evaluate(spec, P1, progress=False)
    assert card["agent"]["name"] == "my_agent:act" and card["agent"]["spec"] == spec  # the spec still replays it
    policy = evaluate(str(POLICY), P1, progress=False)
    assert policy["agent"]["name"] == "seed0" and str(ROOT) not in policy["agent"]["name"]
    assert evaluate(spec, P1, progress=False, name="my-agent")["agent"]["name"] == "my-agent"


def test_the_leaderboard_refuses_a_submission_named_after_a_path(board_root, tmp_path):
    from billiards.bench.leaderboard import build

    spec = f"{agent_file(tmp_path / 'home' / 'me')}:act"
    out = board_root / "submissions" / P3 / "mine"
    evaluate(spec, P3, out=out, progress=False, name=spec)  # the path given as its name
    with pytest.raises(ValueError, match=r"submissions/p3-exact-v1/mine/scorecard\.json: its agent's name '.*my_agent\.py:act' "
                                         r"is a path, not a name.*name=<your agent's name>"):
        build(board_root, tmp_path / "out", figure=False)
    shutil.rmtree(out)
    evaluate(spec, P3, out=out, progress=False)  # no name given: named after the file's stem, and ranked
    board, _ = build_board(board_root, tmp_path / "out")
    assert "my_agent:act" in {r["row"] for r in board["tracks"][P3]["rows"]}


def test_a_path_given_as_the_group_is_refused_too(board_root, tmp_path):
    from billiards.bench.leaderboard import build

    evaluate("random", P3, out=board_root / "submissions" / P3 / "grouped", progress=False, name="mine",
             group="/srv/me/runs/sac")
    with pytest.raises(ValueError, match=r"its agent's group '/srv/me/runs/sac' is a path.*again with group=<the row's name>"):
        build(board_root, tmp_path / "out", figure=False)


# ----------------------------------------------------------------------------- 2. a scorecard claims no status


def test_a_scorecard_claims_no_status_and_the_board_gives_it_one(board_root, tmp_path):
    card = evaluate(zeros, P1, progress=False)
    assert "verified" not in card and "status" not in card
    theirs = board_root / "submissions" / P3 / "theirs" / SCORECARD_JSON
    assert "verified" not in json.loads(theirs.read_text())
    older = dict(json.loads(theirs.read_text()), verified=True)  # what older scorecards said of themselves
    theirs.write_text(json.dumps(older, indent=2) + "\n")
    board, _ = build_board(board_root, tmp_path / "out")
    rows = {r["row"]: r for r in board["tracks"][P3]["rows"]}
    assert rows["their-agent"]["status"] == "unverified" and rows["random row"]["status"] == "verified"
    assert "verified" not in json.dumps(rows["their-agent"]).replace('"unverified"', "")


# ----------------------------------------------------------------------------- 3. what the rebuild leaves out, it says


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_the_rebuild_names_each_partial_or_limited_scorecard_it_leaves_out(board_root, tmp_path):
    evaluate("nearest", P3, out=board_root / "submissions" / P3 / "quick", progress=False, name="quick", limit=3)
    cut = board_root / "submissions" / P3 / "cut"
    evaluate("random_aim", P3, out=cut, progress=False, name="cut")
    card = json.loads((cut / SCORECARD_JSON).read_text())
    (cut / SCORECARD_JSON).write_text(json.dumps(dict(card, partial=True, units_done=7)))  # as an interrupted run leaves it
    lines: list[str] = []
    board, _ = build_board(board_root, tmp_path / "out", report=lines.append)
    assert {r["row"] for r in board["tracks"][P3]["rows"]} == {"random row", "nearest row", "their-agent"}
    assert sorted(lines) == [
        f"left out {cut / SCORECARD_JSON}: partial, 7 units finished: the same command with out=<its directory> plays the rest",
        f"left out {board_root / 'submissions' / P3 / 'quick' / SCORECARD_JSON}: limited to 3 units per opponent or track "
        "(limit=): play the whole track, without limit="]
    proc = bench_cli("leaderboard", "--scorecards", str(board_root), "--out", str(tmp_path / "cli"), "--no-figure")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert [line for line in proc.stderr.splitlines() if line.startswith("left out")] == sorted(lines)


# ----------------------------------------------------------------------------- 4. the project's rows and outside rows, counted apart


def test_the_board_counts_outside_submissions_apart(board_root, tmp_path):
    board, md = build_board(board_root, tmp_path / "out")
    assert (board["agents"], board["scorecards"]) == (2, 2)  # the project's: random row, nearest row
    assert board["outside"] == {"agents": 1, "scorecards": 1}
    assert list(board) == ["rebuild", "agents", "scorecards", "outside", "tracks", "compute_curves"]
    header = md.splitlines()[2]
    assert header.startswith("Every agent of the project on every track it applies to (2 agents, 2 scorecards), and 1 outside "
                             "agent submitted to it (1 scorecard; status unverified). Rebuilt by")
    shutil.rmtree(board_root / "submissions")
    board, md = build_board(board_root, tmp_path / "own")
    assert "outside" not in board and (board["agents"], board["scorecards"]) == (2, 2)
    assert md.splitlines()[2].startswith("Every agent of the project on every track it applies to (2 agents, 2 scorecards). "
                                         "Rebuilt by")


# ----------------------------------------------------------------------------- 5. where it looked, when it finds nothing


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_the_rebuild_says_where_it_looked_when_it_finds_no_scorecards(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    for folder in (empty, tmp_path / "missing"):
        proc = bench_cli("leaderboard", "--scorecards", str(folder), "--out", str(tmp_path / "out"), cwd=tmp_path)
        assert proc.returncode == 1 and "no scorecards to rank under " + str(folder) in proc.stderr, proc.stderr
        assert "nothing written" in proc.stderr and "--scorecards DIR" in proc.stderr
    assert "scorecards/*/*/scorecard.json" in bench_cli("leaderboard", "--scorecards", str(empty), cwd=tmp_path).stderr
    assert "(no such folder)" in bench_cli("leaderboard", "--scorecards", str(tmp_path / "missing"), cwd=tmp_path).stderr
    assert not (tmp_path / "out").exists()


def test_outside_a_checkout_the_rebuild_writes_only_where_told(board_root, tmp_path, monkeypatch, capsys):
    import billiards.bench.__main__ as bench_main

    monkeypatch.setattr(bench_main, "IN_CHECKOUT", False)
    before = {p: p.stat().st_mtime_ns for p in (ROOT / "results").glob("leaderboard*")}
    with pytest.raises(SystemExit, match="outside a source checkout give --out DIR"):
        bench_main.main(["leaderboard", "--scorecards", str(board_root), "--no-figure"])
    with pytest.raises(SystemExit, match="campaign writes under the repository's results/"):
        bench_main.main(["campaign", "--only", "nothing-matches"])
    assert {p: p.stat().st_mtime_ns for p in (ROOT / "results").glob("leaderboard*")} == before
    assert bench_main.main(["leaderboard", "--scorecards", str(board_root), "--out", str(tmp_path / "out"), "--no-figure"]) == 0
    assert (tmp_path / "out" / "leaderboard.json").is_file()


# ----------------------------------------------------------------------------- 6. from Python, files only with out=


def test_evaluate_in_python_writes_nothing_without_out(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    card = evaluate(zeros, P1, progress=False)
    assert card["units_done"] == P1.n_blocks() and list(tmp_path.iterdir()) == []
    evaluate(zeros, P1, progress=False, out="here")
    assert sorted(p.name for p in (tmp_path / "here").iterdir()) == ["evaluation.json", "scorecard.json", "scorecard.md",
                                                                     "units.jsonl"]


# ----------------------------------------------------------------------------- 7. placement

SYNTHETIC = {"tracks": {P3: {"version": 1, "rows": [
    {"row": "b", "score": 2.0}, {"row": "top", "score": 3.0}, {"row": "a", "score": 2.0}, {"row": "low", "score": 1.0}]}}}


@pytest.mark.parametrize("value, sentence", [
    (4.0, "would rank 1 of 5 on p3-exact-v1, above top (3.00)"),
    (2.5, "would rank 2 of 5 on p3-exact-v1, between top (3.00) and a (2.00)"),
    (2.0, "would rank 2 of 5 on p3-exact-v1, tied with a (2.00) and b (2.00)"),
    (3.0, "would rank 1 of 5 on p3-exact-v1, tied with top (3.00)"),
    (1.5, "would rank 4 of 5 on p3-exact-v1, between b (2.00) and low (1.00)"),
    (0.0, "would rank 5 of 5 on p3-exact-v1, below low (1.00)"),
])
def test_placement_on_a_small_board(value, sentence, tmp_path):
    from billiards.bench.leaderboard import placement

    assert placement(P3, value, SYNTHETIC) == sentence
    (tmp_path / "board.json").write_text(json.dumps(SYNTHETIC))
    assert placement(P3, value, tmp_path / "board.json") == sentence


def test_placement_formats_as_the_board_and_refuses_what_it_cannot_place(tmp_path):
    from billiards.bench.leaderboard import placement

    p1 = {"tracks": {"p1-exact-v1": {"version": 1, "rows": [{"row": "x", "score": 0.5}]}}}
    assert placement("p1-exact-v1", 0.25, p1) == "would rank 2 of 2 on p1-exact-v1, below x (50.00 %)"
    assert placement("p1-exact-v1", 0.25, {"tracks": {"p1-exact-v1": {"rows": []}}}) == \
        "would rank 1 of 1 on p1-exact-v1 (the first row on it)"
    with pytest.raises(ValueError, match="no track 'innings-v1'"):
        placement("innings-v1", 5.0, p1)
    with pytest.raises(ValueError, match="ranks p1-exact-v1 version 1, the score is of version 2"):
        placement("p1-exact-v1", 0.25, p1, version=2)
    with pytest.raises(ValueError, match="no leaderboard to place it on"):
        placement("p1-exact-v1", 0.25, tmp_path / "none.json")


def test_placement_on_the_committed_snapshot():
    """Between each two neighbouring rows of different figures, above the first and below the last,
    on the snapshot :func:`placement` reads by default."""
    from billiards.bench.leaderboard import format_score, placement, snapshot_path
    from billiards.bench.tracks import TRACKS

    assert snapshot_path() == SNAPSHOT
    board = json.loads(SNAPSHOT.read_text())
    for track, entry in board["tracks"].items():
        rows, fmt = entry["rows"], (lambda v: format_score(TRACKS[track].protocol, v))
        if not rows:
            continue
        n = len(rows) + 1
        assert placement(track, rows[0]["score"] + 1) == f"would rank 1 of {n} on {track}, above {rows[0]['row']} ({fmt(rows[0]['score'])})"
        assert placement(track, rows[-1]["score"] - 1) == \
            f"would rank {n} of {n} on {track}, below {rows[-1]['row']} ({fmt(rows[-1]['score'])})"
        for i, (a, b) in enumerate(zip(rows, rows[1:])):
            if a["score"] > b["score"]:
                assert placement(track, (a["score"] + b["score"]) / 2) == \
                    f"would rank {i + 2} of {n} on {track}, between {a['row']} ({fmt(a['score'])}) and {b['row']} ({fmt(b['score'])})"


def test_a_scorecards_headline_is_the_figure_the_board_ranks_its_row_by():
    from billiards.bench.leaderboard import headline_value, placement

    board = json.loads(SNAPSHOT.read_text())
    checked = 0
    for track, entry in board["tracks"].items():
        for row in entry["rows"]:
            if row["status"] != "verified" or len(row["sources"]) != 1:
                continue
            card = json.loads((ROOT / row["sources"][0]).read_text())
            assert headline_value(card) == pytest.approx(row["score"], abs=1e-6), row["sources"][0]
            assert f"{row['row']} (" in placement(track, headline_value(card), board).split("tied with", 1)[1]
            checked += 1
    assert checked > 50


def _evaluate_cfg(**overrides):
    from omegaconf import OmegaConf

    from billiards.bench.config import EvaluateConfig

    return OmegaConf.merge(OmegaConf.structured(EvaluateConfig), {"threads": None, **overrides})


def test_evaluate_py_ends_with_the_placement_line(tmp_path, capsys):
    from billiards.bench.cli import run
    from billiards.bench.leaderboard import headline_value, placement

    card = run(_evaluate_cfg(agent="random", track=P3, name="my-random"), str(tmp_path / "full"))
    out = capsys.readouterr().out.splitlines()
    # an observation agent: its overall place, then its place in the no-simulator division
    assert out[-1] == (f"placement: my-random {placement(P3, headline_value(card))}; it "
                       f"{placement(P3, headline_value(card), division=True)}")
    assert "would rank" in out[-1] and "in the no-simulator division of p3-exact-v1" in out[-1] and "limited" not in out[-1]
    run(_evaluate_cfg(agent="nearest", track=P3, limit=2), str(tmp_path / "quick"))
    out = capsys.readouterr().out.splitlines()
    assert out[-2].startswith("placement: nearest would rank ")
    assert out[-2].endswith("; but a limited run (2 units per opponent or track) is a quick look, not comparable to the "
                            "full-track rows nor a leaderboard entry")
    assert out[-1] == ("name: the scorecard names the agent 'nearest' (from its spec); a submission to the leaderboard needs "
                       "name=<your agent's name>")
    run(_evaluate_cfg(agent="random", track=P3, progress=False), str(tmp_path / "quiet"))
    assert capsys.readouterr().out == ""


# ----------------------------------------------------------------------------- 8. the framework's failures are not the agent's
# (a dependency missing in a fresh interpreter: tests/test_fresh_interpreter.py)


def _env_that(monkeypatch, fails):
    """The vector env every innings track plays through, replaced by one that fails as ``fails``."""
    import billiards.envs.gym_vector as gym_vector

    monkeypatch.setattr(gym_vector, "Billiards4BallVectorEnv", lambda *args, **kwargs: fails())


def test_an_extra_the_framework_needs_is_named_with_the_extra_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)  # as if not installed

    def needs_sb3():
        import stable_baselines3  # noqa: F401

    _env_that(monkeypatch, needs_sb3)
    with pytest.raises(EvaluationError) as err:
        evaluate("random", P1, progress=False)
    msg = str(err.value)
    assert msg.startswith("the evaluation cannot play inning block 0 of p1-exact-v1: it needs stable_baselines3, which is not "
                          "installed") and 'install it: pip install "sagu-bench[sb3]"' in msg
    assert "agent random failed" not in msg and "Not a failure of agent random" in msg


def test_an_error_outside_the_agents_calls_is_not_put_on_the_agent(monkeypatch):
    def breaks():
        raise RuntimeError("the table broke")

    _env_that(monkeypatch, breaks)
    with pytest.raises(EvaluationError, match=r"^the evaluation failed on inning block 0 of p1-exact-v1, outside agent random's "
                                              r"calls: RuntimeError: the table broke \(0 finished units kept\)$"):
        evaluate("random", P1, progress=False)


def test_an_agents_own_failures_are_still_its_own():
    class NeedsJax(Agent):
        def act(self, obs, tables, levels):
            import billiards_no_such_module_jax  # noqa: F401

    with pytest.raises(EvaluationError, match=r"^agent mine failed on inning block 0 of p1-exact-v1: ModuleNotFoundError"):
        evaluate(NeedsJax("mine"), P1, progress=False)

    class Fumbles(Agent):
        def act(self, obs, tables, levels):
            raise ZeroDivisionError("no table")

    match = dataclasses.replace(get_track("match-x5-v1"), units=1, opponents=("random",), ratings=(("random", 1000.0),),
                                anchor="random", target=2)
    with pytest.raises(EvaluationError, match=r"^agent fumbles failed on match 0 of match-x5-v1: ZeroDivisionError"):
        evaluate(Fumbles("fumbles"), match, progress=False)


def test_the_install_of_an_extra_or_a_dependency():
    from billiards.bench.extras import install_hint

    assert install_hint("stable_baselines3") == 'pip install "sagu-bench[sb3]"'
    assert install_hint("stable_baselines3.common.env_checker") == 'pip install "sagu-bench[sb3]"'
    assert install_hint("pygame") == 'pip install "sagu-bench[render]"'
    assert install_hint("hydra_plugins.hydra_optuna_sweeper") == 'pip install "sagu-bench[optuna]"'
    assert install_hint("minari") == 'pip install "sagu-bench[offline]"'  # not the test extra
    assert install_hint("pettingzoo").startswith('pip install "pettingzoo') and "a dependency of sagu-bench" in install_hint("pettingzoo")
    assert install_hint("hydra").startswith('pip install "hydra-core')
    assert install_hint("jax") == "pip install jax"


def test_an_sb3_spec_without_stable_baselines3_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "stable_baselines3", None)
    with pytest.raises(AgentError, match=r'Stable-Baselines3 is not installed \(pip install "sagu-bench\[sb3\]"\)'):
        evaluate("sb3:sac:model.zip", P1, progress=False)
