"""search.py's run directory: what it says up front, what it keeps when interrupted, and
``resume=`` continuing a stopped P3 to the same result as an uninterrupted run."""

import json

import pytest

from billiards.search import run as search_run
from billiards.search.config import search_config
from billiards.search.proposers import GeometricProposer


def small_cfg(**protocol):
    name = protocol.get("name", "p3")
    cfg = search_config(protocol=name)
    if name == "p3":
        cfg.protocol.seeds, cfg.protocol.cap = 4, 12
    else:
        cfg.protocol.n_innings, cfg.protocol.shots = 3, 3
    cfg.search.budget, cfg.search.k1, cfg.search.m1 = 90, 60, 3
    cfg.progress, cfg.picture = False, False
    return cfg


def interrupt_after(monkeypatch, n_calls):
    """Make the proposer raise KeyboardInterrupt (a Ctrl-C) on its n-th call."""
    original, calls = GeometricProposer.propose, [0]

    def propose(self, *args, **kwargs):
        calls[0] += 1
        if calls[0] == n_calls:
            raise KeyboardInterrupt
        return original(self, *args, **kwargs)

    monkeypatch.setattr(GeometricProposer, "propose", propose)
    return calls


def test_p3_interrupted_keeps_finished_chains_and_resumes_to_the_same_result(tmp_path, monkeypatch, capsys):
    whole = search_run.run(small_cfg(), tmp_path / "whole")
    assert len(whole.values) == 4 and (tmp_path / "whole" / "config.yaml").is_file()
    out = capsys.readouterr().out
    assert "P3: 4 chains from the opening rack, each up to 12 shots" in out and f"output: {tmp_path / 'whole'}" in out
    assert f"results: {tmp_path / 'whole' / 'results.json'}" in out

    lengths = whole.values
    # interrupt inside the third chain: two proposer calls per decision (depth 1 and 2)
    decisions_before = lengths[0] + 1 + lengths[1] + 1
    interrupt_after(monkeypatch, 2 * decisions_before + 1)
    stopped = tmp_path / "stopped"
    with pytest.raises(SystemExit) as exit_info:
        search_run.run(small_cfg(), stopped)
    assert exit_info.value.code == 130
    partial = json.loads((stopped / "results.json").read_text())
    assert partial["extra"]["partial"] and partial["values"] == lengths[:2]
    assert "continue with: python search.py resume=" in capsys.readouterr().out
    monkeypatch.undo()

    resumed_cfg = small_cfg()
    resumed_cfg.resume = str(stopped)
    resumed = search_run.run(resumed_cfg, stopped)
    assert "resume: 2 of 4 chains already finished" in capsys.readouterr().out
    assert resumed.values == lengths and resumed.mean == whole.mean
    final = json.loads((stopped / "results.json").read_text())
    assert "partial" not in final["extra"] and final["values"] == lengths


def test_a_fresh_run_never_counts_the_chains_of_an_earlier_run_in_its_directory(tmp_path, capsys):
    """Only resume= continues a run's chains: a fresh run with another config in the same
    directory (an explicit hydra.run.dir, a --redo) plays every chain itself."""
    first = search_run.run(small_cfg(), tmp_path)
    assert max(first.values) > 3  # some chain of the first run is longer than the second's cap
    again = small_cfg()
    again.protocol.cap = 3
    second = search_run.run(again, tmp_path)
    assert "fresh run: discarding 4 chains of an earlier run" in capsys.readouterr().out
    assert max(second.values) <= 3 and len(second.values) == 4
    ledger = [json.loads(line) for line in (tmp_path / "chains.jsonl").read_text().splitlines()]
    assert [r["length"] for r in ledger] == second.values


def test_p1_interrupted_writes_a_partial_result(tmp_path, monkeypatch, capsys):
    interrupt_after(monkeypatch, 5)  # two proposer calls per batched step, after the collector's first probe
    with pytest.raises(SystemExit) as exit_info:
        search_run.run(small_cfg(name="p1"), tmp_path)
    assert exit_info.value.code == 130
    res = json.loads((tmp_path / "results.json").read_text())
    done = res["extra"]["shots_done"]
    assert res["extra"]["partial"] and 1 <= done < 3 and len(res["values"]) == 3 and res["shots"] == 3 * done
    assert f"{done} of 3 shots per inning finished" in capsys.readouterr().out


def test_resume_of_a_directory_that_is_no_search_run_fails_clearly(tmp_path):
    cfg = small_cfg()
    cfg.resume = str(tmp_path)
    with pytest.raises(ValueError, match="no config.yaml there"):
        search_run.run(cfg, tmp_path)


SEARCH_BAD = [
    (["seed=-1"], "seed must be >= 0"),
    (["search=puct", "search.c_puct=nan"], "search (puct): PUCT needs finite c_puct >= 0"),
    (["search=puct", "search.gamma=1.5"], "search (puct): gamma must lie in [0, 1], got 1.5"),
    (["search.foul_penalty=-1"], "search (h2): foul_penalty must be a finite number >= 0, got -1.0"),
    (["proposer.power_low=0.95"], "proposer.power_low and proposer.power_high must satisfy"),
    (["threads=0"], "threads must be an integer in [1, "),
    (["threads=100000"], "threads must be an integer in [1, "),
    (["search.budget=10000000000000"], "search.budget=10000000000000: integers here must lie within +-2,147,483,647"),
    (["+hydra.callbacks.evil._target_=pathlib.Path.touch", "+hydra.callbacks.evil.self=pwned"], "configs are data here"),
    (["proposer._target_=builtins.print"], "configs are data here"),
    (["--experimental-rerun", "config.pickle"], "the flag --experimental-rerun is not accepted here"),
    (["physics=bogus"], "Could not find 'physics/bogus'"),
    (["search=h2", "search.c_puct=5"], "Key 'c_puct' not in 'H2Config'"),  # a PUCT knob
    (["search=h2", "+search.c_puct=5"], "search.c_puct: not a key of H2Config"),
    (["protocol=p3", "protocol.shots=5"], "Key 'shots' not in 'P3Config'"),
]  # a multirun's bad job: tests/apps/test_composition_guard.py


def _through_the_app(overrides) -> bool:
    """The cases only the entry point shows (flags, a callback that would run code; a multirun's:
    tests/apps/test_composition_guard.py) and one refusal of each step: the guard, Hydra's
    composition, the validator."""
    return overrides[0].startswith(("-", "+hydra")) or overrides in (["physics=bogus"], ["search=h2", "search.c_puct=5"], ["seed=-1"])


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", [b for b in SEARCH_BAD if "-m" not in b[0] and not b[0][0].startswith("--")],
                         ids=[" ".join(o) for o, _ in SEARCH_BAD if "-m" not in o and not o[0].startswith("--")])
def test_each_bad_search_override_is_refused_with_its_message(tmp_path, overrides, message):
    from conftest import refusal

    said = refusal("search.py", *overrides, cwd=tmp_path)
    assert message in said, said
    assert list(tmp_path.iterdir()) == [], f"wrote {list(tmp_path.rglob('*'))}"


@pytest.mark.slow
@pytest.mark.parametrize("overrides,message", [b for b in SEARCH_BAD if _through_the_app(b[0])],
                         ids=[" ".join(o) for o, _ in SEARCH_BAD if _through_the_app(o)])
def test_bad_search_overrides_fail_fast_and_write_nothing(tmp_path, overrides, message):
    from conftest import app_here

    proc = app_here("search.py", *overrides, cwd=tmp_path)
    assert proc.returncode != 0 and message in proc.stderr, proc.stderr
    assert not (tmp_path / "pwned").exists()
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == [], f"wrote {list(tmp_path.rglob('*'))}"


def test_a_malformed_chain_ledger_is_refused_clearly_on_resume(tmp_path):
    """A chains.jsonl line that is no chain record (other than a torn last line) stops a resume
    with the file and the line named, no traceback; a torn last line is still ignored."""
    from billiards.search.protocols import read_chains

    stopped = tmp_path / "run"
    search_run.run(small_cfg(), stopped)
    ledger = stopped / "chains.jsonl"
    lines = ledger.read_text().splitlines()
    ledger.write_text("\n".join(lines[:2]) + '\n{"seed": 9, "len')  # torn: ignored
    assert sorted(read_chains(ledger)) == [0, 1]
    ledger.write_text('{"seed": "zero", "length": 3}\n' + "\n".join(lines[1:]) + "\n")
    cfg = small_cfg()
    cfg.resume = str(stopped)
    with pytest.raises(SystemExit, match=r"cannot resume: .*chains.jsonl: line 1 is not an intact P3 chain record"):
        search_run.run(cfg, stopped)
    # each line carries a checksum: a chain whose length was changed by hand is refused too
    edited = json.loads(lines[0])
    edited["length"] += 1
    ledger.write_text(json.dumps(edited) + "\n" + "\n".join(lines[1:]) + "\n")
    with pytest.raises(SystemExit, match=r"line 1 is not an intact P3 chain record"):
        search_run.run(cfg, stopped)
