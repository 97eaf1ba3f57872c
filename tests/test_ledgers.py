"""Ledgers that cannot lie: a P3's ``chains.jsonl`` and a league's ``matches.jsonl`` hold one
sealed record a line, each carrying its run's identity (billiards.files: ``append_record``,
``read_ledger``, ``run_identity``). A resume refuses an unsealed, edited, foreign or repeated
record with a sentence naming the file and the line, cuts a torn last line off and plays its
unit again; ``python -m billiards.files verify`` checks a run directory's ledger and summary."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from billiards.files import (CHAINS, MATCHES, RUN_KEY, SEAL_KEY, LedgerError, append_record, main as files_main,
                             read_ledger, run_identity, sealed_record)
from billiards.search import run as search_run
from billiards.search.config import search_config
from billiards.search.protocols import read_chains

ROOT = Path(__file__).resolve().parents[1]


# ----------------------------------------------------------------------------- a tiny P3


def tiny_p3(budget: int = 90):
    cfg = search_config(protocol="p3")
    cfg.protocol.seeds, cfg.protocol.cap = 3, 8
    cfg.search.budget, cfg.search.k1, cfg.search.m1 = budget, 60, 3
    cfg.progress, cfg.picture = False, False
    return cfg


def resume(run_dir: Path, **changes):
    cfg = tiny_p3()
    for k, v in changes.items():
        cfg[k] = v
    cfg.resume = str(run_dir)
    return search_run.run(cfg, run_dir)


@pytest.fixture(scope="module")
def p3_runs(tmp_path_factory):
    """Two finished tiny P3 runs, one at another search budget (the same seeds)."""
    root = tmp_path_factory.mktemp("p3")
    whole = search_run.run(tiny_p3(), root / "whole")
    other = search_run.run(tiny_p3(budget=60), root / "other")
    return root, whole.values, other.values


def copy_run(p3_runs, tmp_path, name: str = "whole") -> tuple[Path, list[str]]:
    root = p3_runs[0]
    run_dir = tmp_path / "run"
    shutil.copytree(root / name, run_dir)
    return run_dir, (run_dir / "chains.jsonl").read_text().splitlines()


def test_the_identity_leaves_out_runtime_keys_and_every_record_carries_it(p3_runs, tmp_path):
    assert run_identity({"budget": 90, "threads": 1}, runtime=("threads",)) == run_identity({"budget": 90, "threads": 8},
                                                                                            runtime=("threads",))
    assert run_identity({"budget": 90}) != run_identity({"budget": 60})
    run_dir, lines = copy_run(p3_runs, tmp_path)
    ident = search_run.search_identity(run_dir)
    records = [json.loads(x) for x in lines]
    assert all(r[RUN_KEY] == ident and r[SEAL_KEY] == sealed_record(r)[SEAL_KEY] for r in records)
    assert json.loads((run_dir / "results.json").read_text())["run"] == ident
    assert ident != search_run.search_identity(p3_runs[0] / "other")  # another budget: another run
    # a resume with other runtime keys (threads, progress, picture) is the same run: nothing is played again
    again = resume(run_dir, threads=1, progress=False)
    assert again.values == p3_runs[1] and (run_dir / "chains.jsonl").read_text().splitlines() == lines


def test_an_unsealed_line_is_refused_on_resume(p3_runs, tmp_path, capsys):
    """The trial's case: the last chain's sealed line replaced by an unsealed one claiming 9999."""
    run_dir, lines = copy_run(p3_runs, tmp_path)
    last = json.loads(lines[-1])
    forged = {"seed": last["seed"], "length": 9999, "decisions": 1, "seconds": 0.1, "last_shots": []}
    (run_dir / "chains.jsonl").write_text("\n".join(lines[:-1]) + "\n" + json.dumps(forged) + "\n")
    with pytest.raises(SystemExit, match=r"cannot resume: .*chains.jsonl: line 3 is not an intact P3 chain record: "
                                         r"it carries no seal"):
        resume(run_dir)
    # with the run's identity but no seal: the same
    (run_dir / "chains.jsonl").write_text("\n".join(lines[:-1]) + "\n" + json.dumps({**forged, RUN_KEY: last[RUN_KEY]}) + "\n")
    with pytest.raises(SystemExit, match=r"line 3 is not an intact P3 chain record: it carries no seal"):
        resume(run_dir)
    # sealed but without a run identity (ledgers between the seals and the identities)
    bare = sealed_record({k: v for k, v in last.items() if k != RUN_KEY})
    (run_dir / "chains.jsonl").write_text("\n".join(lines[:-1]) + "\n" + json.dumps(bare) + "\n")
    with pytest.raises(SystemExit, match=r"line 3 is not an intact P3 chain record: it carries no run identity"):
        resume(run_dir)


def test_a_sealed_line_of_another_run_is_refused(p3_runs, tmp_path):
    """A line copied from a run at another search budget is sealed, but not this run's."""
    run_dir, lines = copy_run(p3_runs, tmp_path)
    other = (p3_runs[0] / "other" / "chains.jsonl").read_text().splitlines()
    (run_dir / "chains.jsonl").write_text("\n".join([lines[0], other[1], lines[2]]) + "\n")
    with pytest.raises(SystemExit, match=r"cannot resume: .*chains.jsonl: line 2 belongs to another run \(run '[0-9a-f]{16}'; "
                                         r"this run is [0-9a-f]{16}\)"):
        resume(run_dir)
    (run_dir / "chains.jsonl").write_text("\n".join(other) + "\n")  # the whole ledger swapped
    with pytest.raises(SystemExit, match=r"line 1 belongs to another run"):
        resume(run_dir)


def test_an_edited_or_repeated_chain_is_refused(p3_runs, tmp_path):
    run_dir, lines = copy_run(p3_runs, tmp_path)
    edited = json.loads(lines[1])
    edited["length"] += 5
    (run_dir / "chains.jsonl").write_text("\n".join([lines[0], json.dumps(edited), lines[2]]) + "\n")
    with pytest.raises(SystemExit, match=r"line 2 is not an intact P3 chain record: its content does not match its seal"):
        resume(run_dir)
    (run_dir / "chains.jsonl").write_text("\n".join([lines[0], lines[1], lines[1]]) + "\n")
    with pytest.raises(SystemExit, match=r"line 3 repeats the chain of seed 1, already finished on line 2"):
        resume(run_dir)


def test_a_bare_number_or_a_record_missing_keys_gives_a_sentence(p3_runs, tmp_path):
    run_dir, lines = copy_run(p3_runs, tmp_path)
    ident = json.loads(lines[0])[RUN_KEY]
    for bad, why in (("42", r"it is a JSON number, not a record"), ("[1, 2]", r"it is a JSON array"),
                     (json.dumps(sealed_record({"seed": 2, RUN_KEY: ident})), r"length must be an integer >= 0, got nothing"),
                     (json.dumps(sealed_record({"seed": 2, "length": True, RUN_KEY: ident})),
                      r"length must be an integer >= 0, got a boolean"),
                     (json.dumps(sealed_record({"seed": 2, "length": 1, "decisions": 1, "seconds": 10**400, "last_shots": [],
                                                RUN_KEY: ident})),
                      r"seconds must be a finite number >= 0, got an integer beyond any float"),
                     ("[" * 100_000, r"it is not JSON a ledger reads \(its brackets do not balance\)"),
                     ("[" * 100 + "]" * 100, r"it is not JSON a ledger reads \(it nests deeper than 64 levels\)")):
        (run_dir / "chains.jsonl").write_text("\n".join(lines[:2]) + "\n" + bad + "\n")
        with pytest.raises(SystemExit, match=r"cannot resume: .*chains.jsonl: line 3 is not an intact P3 chain record: " + why):
            resume(run_dir)


def test_a_torn_last_chain_is_cut_and_played_again_to_the_uninterrupted_result(p3_runs, tmp_path, capsys):
    """A kill mid-append leaves the last line without its newline: the resume cuts it, plays its
    chain again and ends equal to the uninterrupted run; a later resume and verify accept the ledger."""
    run_dir, lines = copy_run(p3_runs, tmp_path)
    (run_dir / "results.json").unlink()
    (run_dir / "chains.jsonl").write_text(lines[0] + "\n" + lines[1][: len(lines[1]) // 2])  # killed inside line 2
    with pytest.raises(LedgerError, match="ends in a torn line"):  # an append never glues a record onto a torn line
        append_record(run_dir / "chains.jsonl", {"seed": 1}, "x")
    capsys.readouterr()
    resumed = resume(run_dir)
    out = capsys.readouterr().out
    assert "resume: cut the torn last line of chains.jsonl" in out and "resume: 1 of 3 chains already finished" in out
    assert resumed.values == p3_runs[1]
    ledger = [json.loads(x) for x in (run_dir / "chains.jsonl").read_text().splitlines()]
    assert [r["seed"] for r in ledger] == [0, 1, 2] and [r["length"] for r in ledger] == p3_runs[1]
    assert resume(run_dir).values == p3_runs[1]  # and again: nothing to cut, nothing to play
    assert files_main(["verify", str(run_dir)]) == 0


def test_the_verify_command_catches_a_summary_that_disagrees(p3_runs, tmp_path, capsys):
    run_dir, lines = copy_run(p3_runs, tmp_path)
    assert files_main(["verify", str(run_dir)]) == 0
    assert "ledger and summary agree" in capsys.readouterr().out
    results = json.loads((run_dir / "results.json").read_text())
    results["values"][1] = 9999
    (run_dir / "results.json").write_text(json.dumps(results))
    assert files_main(["verify", str(run_dir)]) == 1
    out = capsys.readouterr().out
    assert f"results.json gives seed 1 the value 9999; the ledger's chain of seed 1 is {p3_runs[1][1]} long" in out
    # a ledger line edited, and one of another run: one line each
    edited = json.loads(lines[0])
    edited["length"] += 1
    other = (p3_runs[0] / "other" / "chains.jsonl").read_text().splitlines()[2]
    (run_dir / "chains.jsonl").write_text("\n".join([json.dumps(edited), lines[1], other]) + "\n")
    assert files_main(["verify", str(run_dir)]) == 1
    problems = [x for x in capsys.readouterr().out.splitlines() if x.startswith("problem:")]
    assert any("line 1 is not an intact P3 chain record: its content does not match its seal" in x for x in problems)
    assert any("line 3 belongs to another run" in x for x in problems)
    assert any("counts seed 0" in x and "which the ledger does not hold" in x for x in problems)


# ----------------------------------------------------------------------------- a tiny league of random players


pytest.importorskip("pettingzoo")


def random_league():
    from billiards.league.players import RandomPlayer, make_agent
    from billiards.physics import DEFAULT_PARAMS
    from billiards.physics.noise import get_noise

    noise = get_noise("fastfiz_x5")
    players = {n: make_agent(RandomPlayer(), noise, DEFAULT_PARAMS) for n in ("r1", "r2")}
    return players, dict(noise=noise, target=1, max_innings=4)


def league(out: Path, **kw):
    from billiards.league.play import run_league

    players, game = random_league()
    args = dict(matches=2, seed=0, noise_name="fastfiz_x5", record={"x": 1}, progress=False, **game)
    args.update(kw)
    return run_league(players, out_dir=out, **args)


def untimed(records):
    return [{k: v for k, v in r.items() if k not in ("cpu_s", SEAL_KEY)} for r in records]


def test_a_league_ledger_refuses_edits_repeats_other_leagues_and_bad_lines(tmp_path):
    first = league(tmp_path / "a")
    path = tmp_path / "a" / "matches.jsonl"
    lines = path.read_text().splitlines()
    assert len(lines) == 4 and all(json.loads(x)[RUN_KEY] == first["run"] for x in lines)
    # an edited winner
    rec = json.loads(lines[1])
    rec["winner"] = "yellow" if rec["winner"] != "yellow" else "white"
    path.write_text("\n".join([lines[0], json.dumps(rec), *lines[2:]]) + "\n")
    with pytest.raises(LedgerError, match=r"matches.jsonl: line 2 is not an intact league match record: its content does "
                                          r"not match its seal"):
        league(tmp_path / "a")
    # a duplicated line
    path.write_text("\n".join([*lines[:3], lines[2]]) + "\n")
    with pytest.raises(LedgerError, match=r"line 4 repeats match 0 of r2 \(white\) vs r1, already finished on line 3"):
        league(tmp_path / "a")
    # the records of a league with other settings (another target)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LedgerError, match=r"line 1 belongs to another run"):
        league(tmp_path / "a", target=2)
    # unsealed; a bare number; a sealed record missing keys: sentences, no KeyError / TypeError
    unsealed = {k: v for k, v in json.loads(lines[0]).items() if k != SEAL_KEY}
    for bad, why in ((json.dumps(unsealed), "it carries no seal"), ("7", r"it is a JSON number, not a record"),
                     (json.dumps(sealed_record({"a": "r1", "b": "r2", RUN_KEY: first["run"]})),
                      "i must be an integer >= 0, got nothing"),
                     (json.dumps(sealed_record({**unsealed, "scores": 3})), "scores must give white and yellow each a number")):
        path.write_text(bad + "\n" + "\n".join(lines[1:]) + "\n")
        with pytest.raises(LedgerError, match=r"line 1 is not an intact league match record: " + why):
            league(tmp_path / "a")
    assert path.read_text().splitlines()[1:] == lines[1:]  # nothing was appended to a refused ledger


def test_a_torn_last_match_is_cut_and_played_again_to_the_uninterrupted_league(tmp_path):
    whole = league(tmp_path / "whole")
    lines = (tmp_path / "whole" / "matches.jsonl").read_text().splitlines()
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "matches.jsonl").write_text("\n".join(lines[:2]) + "\n" + lines[2][:-30])
    again = league(tmp_path / "b")
    strip = lambda pairs: [{k: v for k, v in p.items() if not k.endswith("ms_per_turn")} for p in pairs]  # noqa: E731
    assert strip(again["pairs"]) == strip(whole["pairs"]) and again["run"] == whole["run"]
    replayed = [json.loads(x) for x in (tmp_path / "b" / "matches.jsonl").read_text().splitlines()]
    assert untimed(replayed) == untimed(json.loads(x) for x in lines)
    assert league(tmp_path / "b")["pairs"] == again["pairs"]  # a later start plays nothing and accepts the ledger
    assert files_main(["verify", str(tmp_path / "b")]) == 0


def test_the_verify_command_catches_league_counts_that_disagree(tmp_path, capsys):
    league(tmp_path)
    data = json.loads((tmp_path / "league.json").read_text())
    data["pairs"][0]["a_wins"] += 1
    data["pairs"][0]["matches"] += 1
    (tmp_path / "league.json").write_text(json.dumps(data))
    assert files_main(["verify", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    p = data["pairs"][0]
    assert f"league.json counts {p['a']} vs {p['b']} {p['a_wins']}-{p['b_wins']} with {p['draws']} draws of {p['matches']}; " \
           f"the ledger holds {p['a_wins'] - 1}-{p['b_wins']} with {p['draws']} draws of {p['matches'] - 1}" in out


def _tiny_league(tmp_path):
    """The composed config of a two-player league of one match to one point, and its run folder
    laid out as Hydra lays it (``.hydra/config.yaml`` and ``overrides.yaml``)."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    import billiards.league.config  # noqa: F401  (registers the match app's schema)

    over = ["+agents.r2={kind: random}", "players=[random,r2]", "matches=1", "target=1", "max_innings=4",
            "progress=false", "picture=false"]
    with initialize_config_dir(str(ROOT / "conf"), version_base=None):
        cfg = compose("match", overrides=over)
    out = tmp_path / "run"
    (out / ".hydra").mkdir(parents=True)
    OmegaConf.save(cfg, out / ".hydra" / "config.yaml")  # what Hydra saves
    OmegaConf.save(OmegaConf.create(over), out / ".hydra" / "overrides.yaml")
    return cfg, out


def test_the_match_app_refuses_a_bad_ledger_with_a_sentence(tmp_path):
    """The app (billiards.league.run) continues a league with the identity of its settings as it
    started, whatever the command line's target; a forged line stops it with one sentence."""
    from billiards.league import run

    cfg, out = _tiny_league(tmp_path)
    first = run(cfg, out)
    lines = (out / "matches.jsonl").read_text().splitlines()
    cfg.resume, cfg.target = str(out), 5
    again = run(cfg, out)
    assert again["run"] == first["run"] and again["target"] == 1
    assert (out / "matches.jsonl").read_text().splitlines() == lines
    (out / "matches.jsonl").write_text("3.5\n" + lines[1] + "\n")
    with pytest.raises(SystemExit, match=r"Error: cannot continue the league: .*matches.jsonl: line 1 is not an intact "
                                         r"league match record: it is a JSON number, not a record"):
        run(cfg, out)


# ----------------------------------------------------------------------------- the committed ledgers


def test_committed_ledgers_written_before_the_seals_load_read_only_but_are_never_resumed(tmp_path, capsys):
    """results/ holds ledgers written before ledgers were sealed: read-only views (billiards.compat's
    readers, verify, reports) accept them on their shape; a resume refuses them."""
    from billiards import compat
    from billiards.league.play import parse_matches

    noise_run = ROOT / "results" / "noise" / "runs" / "geo_h2_fastfiz_400_p3"
    assert len(compat.ledger_records(noise_run / "chains.jsonl", CHAINS)) == 100
    with pytest.raises(LedgerError, match=r"line 1 is not an intact P3 chain record: it carries no seal"):
        read_chains(noise_run / "chains.jsonl")
    sagu = ROOT / "results" / "sagu" / "fastfiz_x5_all"
    assert len(parse_matches((sagu / "matches.jsonl").read_text())) == 120
    assert len(compat.ledger_records(sagu / "matches.jsonl", MATCHES)) == 120
    with pytest.raises(LedgerError, match=r"line 1 is not an intact league match record: it carries no seal"):
        read_ledger(sagu / "matches.jsonl", MATCHES)
    assert files_main(["verify", str(noise_run), str(sagu)]) == 0
    out = capsys.readouterr().out
    assert "100 of 100 records carry no seal: their shape is checked" in out
    assert files_main(["verify", "--strict", str(sagu)]) == 1
    # a copy of the committed run, resumed: refused, naming the reason
    shutil.copytree(noise_run, tmp_path / "run")
    (tmp_path / "run" / "results.json").unlink()
    with pytest.raises(SystemExit, match=r"cannot resume: .*chains.jsonl: line 1 is not an intact P3 chain record: it "
                                         r"carries no seal, and an unsealed record cannot be told from an edited one"):
        resume(tmp_path / "run")


@pytest.mark.slow
def test_every_committed_run_directory_verifies():
    """Every committed P3 and league directory: its ledger's records of one run, well formed,
    each unit once, and its summary equal to them (a few seconds)."""
    dirs = sorted({p.parent for k in (CHAINS, MATCHES) for p in (ROOT / "results").rglob(k.file)})
    assert len(dirs) > 100
    assert files_main(["verify", *map(str, dirs)]) == 0


# ----------------------------------------------------------------------------- summaries recomputed on resume


def test_a_results_json_its_chains_do_not_give_is_written_again_on_resume(p3_runs, tmp_path, capsys):
    """A finished P3's results.json is never trusted: one edited to other values or another mean
    is not "finished" (resume=, resume=auto), and the resume writes it again from chains.jsonl,
    playing no chain again."""
    run_dir, lines = copy_run(p3_runs, tmp_path)
    original = json.loads((run_dir / "results.json").read_text())
    assert search_run.resume_state(run_dir, None, True).endswith("is finished (mean %.2f): nothing to do" % original["mean"])
    (run_dir / "results.json").write_text(json.dumps({**original, "values": [99, 99, 99], "mean": 99.0}))
    assert search_run.finished_run(run_dir) is None and search_run.resume_state(run_dir, None, True) is None
    assert files_main(["verify", str(run_dir)]) == 1
    assert "results.json gives seed 0 the value 99" in capsys.readouterr().out
    resume(run_dir)
    out = capsys.readouterr().out
    assert "resume: 3 of 3 chains already finished" in out
    assert "note: " in out and "results.json gives seed 0 the value 99" in out and "written again from chains.jsonl" in out
    again = json.loads((run_dir / "results.json").read_text())
    assert again["values"] == original["values"] == p3_runs[1] and again["mean"] == original["mean"]
    assert (run_dir / "chains.jsonl").read_text().splitlines() == lines  # nothing played again
    assert files_main(["verify", str(run_dir)]) == 0
    # resume=auto over its own directory: an edited mean alone is enough
    (run_dir / "results.json").write_text(json.dumps({**original, "mean": original["mean"] + 1}))
    cfg = tiny_p3()
    cfg.resume = "auto"
    assert search_run.run(cfg, run_dir) is not None  # not "finished: nothing to do"
    assert json.loads((run_dir / "results.json").read_text())["mean"] == original["mean"]
    assert not (run_dir / ".lock").exists()


def test_a_league_json_edited_to_other_elo_values_is_recomputed_on_resume(tmp_path, capsys):
    """league.json's tables are recomputed from matches.jsonl: verify names an Elo rating or a
    score rate that its matches do not give, and a league started again over its directory
    writes them again from the ledger, playing nothing."""
    first = league(tmp_path)
    lines = (tmp_path / "matches.jsonl").read_text().splitlines()
    data = json.loads((tmp_path / "league.json").read_text())
    data["elo"] = {"r1": 1700.0, "r2": 1300.0}
    data["pairs"][0]["a_score_rate"] = 0.99
    data["elo_ci95"]["r2"] = [1000.0, 2000.0]
    (tmp_path / "league.json").write_text(json.dumps(data))
    assert files_main(["verify", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert f"league.json rates r1 at 1700.0 Elo; its matches give {first['elo']['r1']}" in out
    assert f"league.json gives r1 vs r2 a_score_rate 0.99; its matches give {first['pairs'][0]['a_score_rate']}" in out
    lo, hi = first["elo_ci95"]["r2"]
    assert f"league.json gives r2 the Elo interval an array; its matches give [{lo}, {hi}]" in out
    again = league(tmp_path)
    assert "league.json is written again from matches.jsonl" in capsys.readouterr().out
    assert again["elo"] == first["elo"] and again["pairs"] == first["pairs"] and again["elo_ci95"] == first["elo_ci95"]
    assert json.loads((tmp_path / "league.json").read_text())["elo"] == first["elo"]
    assert (tmp_path / "matches.jsonl").read_text().splitlines() == lines
    assert files_main(["verify", str(tmp_path)]) == 0
    bare = {k: v for k, v in again.items() if k != "elo_ci95"}  # a league.json without its intervals: stale, not trusted
    (tmp_path / "league.json").write_text(json.dumps(bare))
    assert files_main(["verify", str(tmp_path)]) == 1
    assert "league.json holds no Elo intervals" in capsys.readouterr().out


def test_the_match_app_calls_a_league_finished_only_when_league_json_is_its_matches(tmp_path, capsys):
    """match.py resume= of a finished league: "nothing to do" when league.json is what its
    matches give; an edited one makes the resume run, and it writes the tables again."""
    from billiards.league import resume_state, run

    cfg, out = _tiny_league(tmp_path)
    first = run(cfg, out)
    cfg.resume = str(out)
    assert resume_state(out, cfg, True).endswith("is finished (2 matches, league.json): nothing to do")
    edited = {**first, "elo": {name: 1500.0 + 300 * (name == "r2") for name in first["elo"]}}
    (out / "league.json").write_text(json.dumps(edited))
    assert resume_state(out, cfg, True) is None
    capsys.readouterr()
    again = run(cfg, out)
    assert "written again from matches.jsonl" in capsys.readouterr().out
    assert again["elo"] == first["elo"] and resume_state(out, cfg, True) is not None
