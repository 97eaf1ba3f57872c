"""Submissions you can trust (issue #57; docs/reliability.md, "Submissions you can trust").

1. The leaderboard recomputes what it ranks: every figure and check comes from a scorecard's
   sealed ledger and its track's rules (billiards.bench.leaderboard.derive), a card that claims
   anything else is refused naming the file, and every outside string is inert in Markdown.
2. Values the contracts refuse elsewhere are refused here too: an agent's answers (real, finite
   numbers only) and its simulation counter (never down), ``evaluation.json`` that is no object,
   an ``out=`` in a system directory, and ``compare`` on cards that cannot be compared.

The forgeries below are written as a forger would: a changed ledger sealed again (a seal proves
a line is whole, it is no signature) and the card recomputed from it, so that the card agrees
with its ledger and only the track's rules can refuse it.
"""

from __future__ import annotations

import dataclasses
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from billiards import files
from billiards.bench import Agent, EvaluationError, evaluate, get_track
from billiards.bench.leaderboard import build, compare
from billiards.bench.run import UNITS_FILE, SCORECARD_JSON, SCORECARD_MD, score_records
from billiards.bench.text import md_code, md_text, one_line, plot_label
from billiards.bench.tracks import TRACKS

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "results" / "bench" / "scorecards"
SNAPSHOT = json.loads((ROOT / "results" / "leaderboard.json").read_text())
P1 = dataclasses.replace(get_track("p1-exact-v1"), units=4, shots=2, block=2)  # two units (blocks of two innings)
P3 = "p3-exact-v1"  # the baselines play the whole track in a fraction of a second


def copy_entry(root: Path, track: str, slug: str, where: str = "submissions") -> Path:
    """A committed scorecard's folder (scorecard, evaluation.json, ledger) copied under ``root``."""
    return Path(shutil.copytree(COMMITTED / track / slug, root / where / track / slug))


def records_of(folder: Path) -> list[dict]:
    return [{k: v for k, v in json.loads(line).items() if k not in ("run", "sha256")}
            for line in (folder / UNITS_FILE).read_text().splitlines()]


def forge(folder: Path, change) -> dict:
    """``change(records)`` applied to the folder's ledger, sealed again under the card's run, and
    the card's figures recomputed from the changed records (it then agrees with its ledger)."""
    card = json.loads((folder / SCORECARD_JSON).read_text())
    records = records_of(folder)
    change(records)
    (folder / UNITS_FILE).unlink()
    for rec in records:
        files.append_record(folder / UNITS_FILE, rec, card["run"])
    card.update(json.loads(json.dumps(score_records(TRACKS[card["track"]], sorted(records, key=lambda r: r["unit"])))))
    (folder / SCORECARD_JSON).write_text(json.dumps(card, indent=2))
    return card


def board_of(root: Path, out: Path) -> tuple[dict, str]:
    paths = build(root, out, figure=False)
    return json.loads(paths[0].read_text()), paths[1].read_text()


def table_lines(md: str, track: str, division: bool = False) -> list[str]:
    """The lines of a track's overall table (``division``: of its no-simulator division's table)."""
    section = md.split(f"## {track}\n", 1)[1].split("\n## ", 1)[0]
    overall, _, rest = section.partition(f"\n### {track}: the no-simulator division")
    return [line for line in (rest if division else overall).splitlines() if line.startswith("|")]


def cells(line: str) -> list[str]:
    """A Markdown table line's cells, split where GitHub splits them (a ``|`` not escaped)."""
    return re.split(r"(?<!\\)\|", line)[1:-1]


# ----------------------------------------------------------------------------- 1. outside strings are inert

FAKE_ROW = "| 1 | fake row | 99.00 [99.00, 99.00] | 99.00 · 99.00 · 1000 · 20 of 20 | | 1 | 0.01 · 0 | observation | verified | |"
MARKUP = ("<img src=x onerror=alert(1)> [click](javascript:alert(1)) ![pixel](http:x) **bold** _it_ `code` $x$ ~~gone~~ "
          "&#124; <b>")  # no slash nor backslash: a name that looks like a path is refused before


@pytest.mark.parametrize("text, inert", [
    ("greedy_r", "greedy_r"),  # existing names stay as they are
    ("SAC aim + features, foul penalty (Table 5)", "SAC aim + features, foul penalty (Table 5)"),
    ("a\nb\r\nc\u2028d\x1b[31m", "a b c d \\[31m"),
    ("a | b", "a \\| b"),
    ("<b>x</b>", "\\<b\\>x\\</b\\>"),
    ("[x](javascript:y)", "\\[x\\](javascript:y)"),
    ("_a_ *b* `c` $d$ ~e~ &lt; !", "\\_a\\_ \\*b\\* \\`c\\` \\$d\\$ \\~e\\~ \\&lt; \\!"),
    ("zero\u200bwidth \u202eright", "zero width right"),
    ("a\\b \\| c", "a\\\\b \\\\\\| c"),
])
def test_md_text_escapes_every_character_with_a_meaning(text, inert):
    assert md_text(text) == inert


def test_code_spans_one_lines_and_plot_labels_are_inert():
    assert md_code("a ` b") == "``a ` b``" and md_code("`x``") == "``` `x`` ```" and md_code("x\ny") == "`x y`"
    assert one_line("  a\n\n b\t") == "a b"
    assert plot_label("cost $5\nnow") == r"cost \$5 now" and plot_label("x" * 60, 48, 46) == "x" * 46 + "..."


def test_an_outside_name_adds_no_row_and_no_markup_to_the_board(tmp_path):
    """A submission named with a newline and a table row of its own, and one whose group is HTML,
    a link, an image and emphasis: each is one row of its own cells, its status the board's, and
    the page rendered holds no HTML, link or image of theirs."""
    root = tmp_path / "bench"
    for slug in ("random", "nearest"):
        copy_entry(root, P3, slug, where="scorecards")
    evaluate("random_aim", P3, out=root / "submissions" / P3 / "evil", progress=False, name="evil\n" + FAKE_ROW + "\n")
    evaluate("random", P3, out=root / "submissions" / P3 / "markup", progress=False, name="markup", group=MARKUP)
    board, md = board_of(root, tmp_path / "out")
    rows = board["tracks"][P3]["rows"]
    assert len(rows) == 4 and sorted(r["status"] for r in rows) == ["unverified", "unverified", "verified", "verified"]
    lines = table_lines(md, P3)
    assert len(lines) == 2 + len(rows)  # the header, its rule and one line per row: none added
    assert all(len(cells(line)) == 10 for line in lines), lines
    assert [c.strip() for line in lines[2:] for c in cells(line)[8:9]].count("verified") == 2
    assert not any(line.startswith("| 1 | fake row") for line in md.splitlines())
    division = table_lines(md, P3, division=True)  # the observation agents again, as inert
    assert len(division) == 2 + len(rows) and all(len(cells(line)) == 7 for line in division), division
    mark = next(line for line in lines if "onerror" in line)
    assert not re.search(r"(?<!\\)[<>\[\]`*$~!&|]", cells(mark)[1].replace("\\\\", "")), mark
    assert {r["row"] for r in rows} >= {"evil\n" + FAKE_ROW + "\n", MARKUP}  # the data keeps the strings as given

    markdown_it = pytest.importorskip("markdown_it")
    html = markdown_it.MarkdownIt("commonmark", {"html": True}).enable(["table", "strikethrough"]).render(md)
    section = html.split('<h2>p3-exact-v1</h2>', 1)[1].split("<h2>", 1)[0]
    assert section.count("<tr>") == 2 * (1 + len(rows))  # each table: the header and the four rows (all observation agents)
    for tag in ("<img", "<a ", "<b>", "<strong>", "<em>", "<code>", "<s>", "<del>"):
        assert tag not in section, tag
    assert "fake row" in section and "onerror=alert(1)" in section  # shown as text


def test_a_scorecard_page_shows_outside_strings_as_text(tmp_path):
    out = tmp_path / "eval"
    name = "mine\n# a heading of theirs\n| 1 | row |"
    evaluate("random", P1, out=out, progress=False, name=name, command="python evaluate.py `rm -rf` <b>x</b>\n## more")
    page = (out / SCORECARD_MD).read_text()
    assert page.splitlines()[0] == "# mine # a heading of theirs \\| 1 \\| row \\| on p1-exact-v1"
    assert not any(line.startswith(("## more", "# a heading", "| 1 | row")) for line in page.splitlines())
    assert "Command: ``python evaluate.py `rm -rf` <b>x</b> ## more`` at commit" in page


# ----------------------------------------------------------------------------- 1. figures from the ledger


def test_the_board_takes_a_match_rows_figures_from_its_ledger(tmp_path):
    """The random agent's 20 sealed losses: its row's win rate, interval, matches, Elo and cost
    are the ledger's even where the card leaves every figure out, and a card claiming 100 % is
    refused naming the file."""
    root = tmp_path / "bench"
    folder = copy_entry(root, "match-x5-v1", "random")
    card = json.loads((folder / SCORECARD_JSON).read_text())
    assert card["match"]["win_rate"] == 0.0 and card["match"]["matches"] == 20
    bare = {k: v for k, v in card.items() if k not in ("match", "elo", "elo_ci95", "values", "ms_per_decision",
                                                       "sims_per_decision", "decisions", "units_done")}
    (folder / SCORECARD_JSON).write_text(json.dumps(bare))
    board, _ = board_of(root, tmp_path / "out")
    row, = board["tracks"]["match-x5-v1"]["rows"]
    committed = next(r for r in SNAPSHOT["tracks"]["match-x5-v1"]["rows"] if r["row"] == row["row"])
    for key in ("score", "elo_ci95", "win_rate", "ci95", "matches", "by_opponent", "ms_per_decision", "sims_per_decision"):
        assert row[key] == committed[key], key
    assert row["status"] == "unverified"

    claims = dict(card, match=dict(card["match"], win_rate=1.0))
    (folder / SCORECARD_JSON).write_text(json.dumps(claims))
    with pytest.raises(ValueError, match=r"submissions/match-x5-v1/random/scorecard\.json: its match\.win_rate \(1\.0\) differs "
                                         r"from what its ledger gives \(0\.0\); the board takes every figure from .*units\.jsonl"):
        build(root, tmp_path / "out", figure=False)
    (folder / SCORECARD_JSON).write_text(json.dumps(dict(card, elo=2400.0)))
    with pytest.raises(ValueError, match=r"its elo \(2400\.0\) differs from what its ledger gives"):
        build(root, tmp_path / "out", figure=False)
    (folder / SCORECARD_JSON).write_text(json.dumps(dict(card, sims_per_decision=0.0, ms_per_decision=0.001)))
    with pytest.raises(ValueError, match=r"its ms_per_decision \(0\.001\) differs"):
        build(root, tmp_path / "out", figure=False)


def test_a_card_renamed_after_it_was_played_is_refused(tmp_path):
    root = tmp_path / "bench"
    folder = copy_entry(root, P3, "nearest")
    card = json.loads((folder / SCORECARD_JSON).read_text())
    (folder / SCORECARD_JSON).write_text(json.dumps(dict(card, agent=dict(card["agent"], name="champion", group="champion"))))
    with pytest.raises(ValueError, match=r"nearest/scorecard\.json: its agent or limit is not the one its ledger was played "
                                         r"with"):
        build(root, tmp_path / "out", figure=False)


def _set(key, value, unit=0, row=None, col=None):
    def change(records):
        rec = next(r for r in records if r["unit"] == unit)
        if row is None:
            rec[key] = value
        elif col is None:
            rec[key][row] = value
        else:
            rec[key][row][col] = value
    return change


def _all_fives(records):
    for r in records:
        r["score"] = [[5] * len(row) for row in r["score"]]


def _extra_unit(unit):
    def change(records):
        records.append(dict(records[-1], unit=unit))
    return change


FORGERIES = {  # (track, committed entry, change, what the refusal says)
    "5 points on one shot": ("innings-v1", "random", _set("score", 5, row=0, col=0), r"its score holds a shot that is not 0 or 1"),
    "50 points per 10-shot inning": ("innings-v1", "random", _all_fives, r"its score holds a shot that is not 0 or 1"),
    "a shot that scores and fouls": ("p1-exact-v1", "nearest", lambda rs: rs[0].update(
        score=[[1] * len(r) for r in rs[0]["score"]], foul=[[1] * len(r) for r in rs[0]["foul"]]), r"a shot both scores and fouls"),
    "a third block of a two-block track": ("innings-v1", "random", _extra_unit(2),
                                           r"unit 2 is not one of innings-v1's 2 units \(0 to 1\)"),
    "a chain numbered 70 in place of the last": ("p3-exact-v1", "random", lambda rs: rs.__setitem__(-1, dict(rs[-1], unit=70)),
                                                    r"unit 70 is not one of p3-exact-v1's 20 units"),
    "a chain past the cap": ("p3-exact-v1", "random", _set("length", 5000), r"its length 5000 is not a whole number in \[0, 1000\]"),
    "a chain of half a shot": ("p3-exact-v1", "random", _set("length", 0.5), r"its length 0\.5 is not a whole number"),
    "a chain that took no decision": ("p3-exact-v1", "random", _set("decisions", 0), r"0 decisions, but a chain of 0 \(cap 1000\) "
                                                                                     r"takes 1"),
    "12 points in a match to 10": ("match-x5-v1", "random", _set("points", [12.0, 0.0]), r"the agent's points 12\.0: outside \[0, 10\]"),
    "a win on fewer points": ("match-x5-v1", "random", _set("winner", "agent"), r"its winner 'agent' is not the one its points"),
    "both at the target": ("match-x5-v1", "random", _set("points", [10.0, 10.0]), r"both players reached 10 points"),
    "a match against another opponent": ("match-x5-v1", "random", _set("opponent", "greedy_r"),
                                         r"match 0 of match-x5-v1 is index 0, opponent 'greedy'"),
    "more points than shots": ("match-x5-v1", "random", lambda rs: rs[0].update(points=[10.0, 0.0], winner="agent", decisions=3),
                               r"the agent scored 10 points with 3 shots"),
    "simulations past the budget": ("p1-exact-v1", "nearest", _set("sims", 401 * 1000),
                                    r"401000 simulations for 1000 decisions, past the track's budget of 400"),
    "an infinite time": ("p1-exact-v1", "nearest", _set("cpu_s", float("inf")), r"its cpu_s inf is not a finite number"),
}


@pytest.mark.parametrize("case", list(FORGERIES))
def test_a_ledger_that_breaks_its_tracks_rules_is_refused_even_when_the_card_agrees(tmp_path, case):
    track, slug, change, says = FORGERIES[case]
    root = tmp_path / "bench"
    folder = copy_entry(root, track, slug)
    board, _ = board_of(root, tmp_path / "before")  # the copy as committed ranks
    assert len(board["tracks"][track]["rows"]) == 1
    forge(folder, change)
    with pytest.raises(ValueError, match=rf"submissions/{track}/{slug}/units\.jsonl: .*{says}"):
        build(root, tmp_path / "out", figure=False)


def test_a_recorded_scorecard_holds_whole_evaluations_within_the_rules(tmp_path):
    root = tmp_path / "bench"
    src = ROOT / "results" / "bench" / "recorded" / "innings-v1" / "sac_plain.json"
    path = root / "recorded" / "innings-v1" / "sac_plain.json"
    path.parent.mkdir(parents=True)
    card = json.loads(src.read_text())
    for values, says in (([11] + card["runs"][0]["values"][1:], r"run 0: unit score 0 \(11\): outside \[0, 10\]"),
                         (card["runs"][0]["values"][:99], r"run 0: 99 unit scores, but a whole evaluation of innings-v1 has 100"),
                         ([None] * 100, r"run 0: unit score 0 \(None\): not a number")):
        path.write_text(json.dumps(dict(card, runs=[dict(card["runs"][0], values=values)])))
        with pytest.raises(ValueError, match=rf"recorded/innings-v1/sac_plain\.json: {says}"):
            build(root, tmp_path / "out", figure=False)
    path.write_text(src.read_text())
    board, _ = board_of(root, tmp_path / "out")
    assert board["tracks"]["innings-v1"]["rows"][0]["status"] == "recorded"


def test_the_scorecard_writer_refuses_a_unit_the_track_does_not_have(tmp_path):
    """A sealed record of unit 7 in the ledger of a two-unit evaluation, or of a shot scoring 3,
    is refused on resume naming the file, never counted."""
    out = tmp_path / "eval"
    card = evaluate("nearest", P1, out=out, progress=False)
    assert len(card["values"]) == 4
    rec = records_of(out)[-1]
    files.append_record(out / UNITS_FILE, dict(rec, unit=7), card["run"])
    with pytest.raises(EvaluationError, match=r"eval/units\.jsonl: unit 7 breaks the rules of p1-exact-v1: unit 7 is not one of "
                                              r"p1-exact-v1's 2 units \(0 to 1\)"):
        evaluate("nearest", P1, out=out, progress=False)

    out2 = tmp_path / "eval2"
    evaluate("nearest", P1, out=out2, progress=False)
    forge(out2, _set("score", 3, unit=1, row=0, col=0))
    with pytest.raises(EvaluationError, match=r"unit 1 breaks the rules of p1-exact-v1: its score holds a shot that is not 0 or 1"):
        evaluate("nearest", P1, out=out2, progress=False)


# ----------------------------------------------------------------------------- 7. what an agent answers


class Raw(Agent):
    """An agent object that returns ``answer(B)`` as its raw shots and moves its counter by ``step``."""

    def __init__(self, answer, step=0, start=0):
        super().__init__("wobbly")
        self.answer, self.step, self.sims = answer, step, start

    def act(self, obs, tables, levels):
        self.sims = self.sims + self.step
        return self.answer(len(tables))


SHOT = [0.0, 0.5, 0.0, 0.0]
BAD_ANSWERS = {
    "complex array": (lambda obs: np.full((len(obs), 4), 0.1 + 0.5j), r"returned complex numbers \(dtype complex128\)"),
    "complex in a list": (lambda obs: [[0.1, 0.2j, 0.0, 0.0]] * len(obs), r"returned complex numbers"),
    "boolean array": (lambda obs: np.ones((len(obs), 4), dtype=bool), r"returned booleans \(dtype bool\)"),
    "a boolean among floats": (lambda obs: [[True, 0.5, 0.0, 0.0]] * len(obs), r"returned booleans"),
    "objects": (lambda obs: np.array([[object()] * 4] * len(obs)), r"returned Python objects \(dtype object\)"),
    "text": (lambda obs: np.array([["a"] * 4] * len(obs)), r"returned text"),
    "infinity": (lambda obs: np.full((len(obs), 4), np.inf), r"returned a non-finite action"),
    "raw complex shots": (Raw(lambda b: np.tile(SHOT, (b, 1)) + 0j), r"returned complex numbers"),
    "raw boolean shots": (Raw(lambda b: np.ones((b, 4), dtype=bool)), r"returned booleans"),
    "raw list of three": (Raw(lambda b: [[0.0, 0.5, 0.0]] * b), r"returned an action of shape \(2, 3\)"),
    "raw NaN shots": (Raw(lambda b: np.full((b, 4), np.nan)), r"returned a non-finite action"),
}


@pytest.mark.parametrize("case", list(BAD_ANSWERS))
def test_an_answer_that_is_not_real_finite_numbers_is_refused_naming_the_agent(case, tmp_path):
    agent, says = BAD_ANSWERS[case]
    with pytest.raises(EvaluationError, match=rf"agent wobbly {says}.*on inning block 0 of p1-exact-v1") as err:
        evaluate(agent, P1, name="wobbly", out=tmp_path / "out", progress=False)
    assert "0 finished units kept" in str(err.value)
    ledger = tmp_path / "out" / UNITS_FILE
    assert not ledger.exists() or not ledger.read_text()  # nothing the agent answered was recorded


def test_a_list_of_plain_numbers_is_still_an_answer():
    card = evaluate(Raw(lambda b: [SHOT] * b), P1, progress=False)
    assert card["values"] == evaluate(Raw(lambda b: np.tile(SHOT, (b, 1))), P1, progress=False)["values"]


@pytest.mark.parametrize("step, start, says", [
    (-7, 100, r"agent wobbly's simulation counter \(sims\) went down from 100 to 93"),
    (0.5, 0, r"agent wobbly's simulation counter \(sims\) is '0\.5', not a whole number >= 0"),
    (0, True, r"agent wobbly's simulation counter \(sims\) is 'True', not a whole number"),
    (-1, 0, r"counter \(sims\) is '-1', not a whole number >= 0"),
    (401 * 2, 0, r"agent wobbly broke the rules of p1-exact-v1 on inning block 0: 1604 simulations for 4 decisions, past the "
                 r"track's budget of 400 per decision"),
])
def test_a_simulation_counter_that_goes_down_or_past_the_budget_is_refused_and_nothing_is_written(tmp_path, step, start, says):
    out = tmp_path / "out"
    with pytest.raises(EvaluationError, match=says):
        evaluate(Raw(lambda b: np.tile(SHOT, (b, 1)), step, start), P1, out=out, progress=False)
    assert not (out / UNITS_FILE).exists() or not (out / UNITS_FILE).read_text()


def test_a_counter_that_only_goes_up_is_reported_per_decision():
    card = evaluate(Raw(lambda b: np.tile(SHOT, (b, 1)), step=6, start=10), P1, progress=False)
    assert card["sims_per_decision"] == 3.0  # 6 a call of two tables


# ----------------------------------------------------------------------------- 7. the run directory


@pytest.mark.parametrize("content", ["[1, 2]", '"evaluation"', "3", "null"])
def test_an_evaluation_json_that_is_not_an_object_gives_a_sentence(tmp_path, content):
    from billiards.bench.config import errors

    out = tmp_path / "eval"
    out.mkdir()
    (out / "evaluation.json").write_text(content)
    with pytest.raises(EvaluationError, match=r"eval/evaluation\.json is not an evaluation's identity \(a JSON object, not "):
        evaluate("nearest", P1, out=out, progress=False)
    errs = errors(_cfg(agent="nearest", out=str(out)))
    assert len(errs) == 1 and "is not an evaluation's identity" in errs[0], errs
    assert sorted(p.name for p in out.iterdir()) == ["evaluation.json"]


def _cfg(**overrides):
    from omegaconf import OmegaConf

    from billiards.bench.config import EvaluateConfig

    return OmegaConf.merge(OmegaConf.structured(EvaluateConfig), overrides)


def _marker_agent(folder: Path) -> str:
    """An agent file that leaves a marker when it is imported (built)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "marked.py"
    path.write_text(f"import pathlib\nimport numpy as np\n\npathlib.Path({str(folder / 'imported')!r}).touch()\n\n\n"
                    "def act(obs):\n    return np.zeros((len(obs), 4))\n")
    return f"{path}:act"


@pytest.mark.parametrize("out", ["/proc/sagu-evaluate/run", "/sys/sagu-evaluate", "/etc/sagu-evaluate", "/dev/sagu-evaluate",
                                 "/usr/lib/sagu-evaluate"])
def test_an_out_in_a_system_directory_is_refused_before_anything_runs(tmp_path, out, monkeypatch):
    import billiards.bench.run as run
    from billiards.bench.config import errors

    def never(out, identity):  # were the refusal to regress, the test writes nothing into the system all the same
        raise AssertionError(f"the evaluation went on to claim {out}")

    monkeypatch.setattr(run, "claim_directory", never)
    spec = _marker_agent(tmp_path / "agent")
    with pytest.raises(EvaluationError, match=rf"out={re.escape(out)}: lies in a system directory"):
        evaluate(spec, P1, out=out, progress=False)
    errs = errors(_cfg(agent=spec, out=out))
    assert errs == [f"out={out}: lies in a system directory ({out}); choose a directory of your own (outputs/evaluate/...)"]
    assert not (tmp_path / "agent" / "imported").exists() and not Path(out).exists()


def test_an_out_that_cannot_be_written_gives_a_sentence(tmp_path, monkeypatch):
    import errno

    import billiards.bench.run as run

    def refuse(path, text):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(run, "atomic_write_text", refuse)
    with pytest.raises(EvaluationError, match=r"out=.*/eval: cannot be written \(Permission denied\); choose a directory"):
        evaluate("nearest", P1, out=tmp_path / "eval", progress=False)


@pytest.mark.slow
def test_evaluate_py_refuses_an_out_in_a_system_directory_in_one_line(tmp_path):
    from conftest import app_here

    proc = app_here("evaluate.py", "agent=nearest", "out=/sys/sagu-evaluate", cwd=tmp_path)
    assert proc.returncode != 0 and "out=/sys/sagu-evaluate: lies in a system directory" in proc.stderr + proc.stdout
    assert "Traceback" not in proc.stderr + proc.stdout


# ----------------------------------------------------------------------------- 7. compare never prints nan


def _card(tmp_path: Path, name: str, values) -> Path:
    card = json.loads((COMMITTED / "innings-v1" / "random" / SCORECARD_JSON).read_text())
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(dict(card, values=values, agent=dict(card["agent"], name=name))))
    return path


def _compare_cli(a: Path, b: Path):
    """``python -m billiards.bench compare a b``, in this process (conftest.app_here)."""
    from conftest import app_here

    return app_here("billiards.bench", "compare", str(a), str(b), cwd=ROOT)


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_compare_refuses_cards_it_cannot_compare_and_never_says_nan(tmp_path):
    empty = _card(tmp_path, "empty", [])
    with pytest.raises(ValueError, match=r"hold 0 unit scores each, but a whole evaluation of innings-v1 has 100: they cannot be "
                                         r"compared"):
        compare(empty, _card(tmp_path, "empty2", []))
    for values, says in (([float("nan")] * 100, r"unit score 0 \(nan\): not a finite number on innings-v1"),
                         ([None] * 100, r"unit score 0 \(None\): not a number but NoneType on innings-v1"),
                         ([11] * 100, r"unit score 0 \(11\): outside \[0, 10\] on innings-v1"),
                         ("3", r"its unit scores must be a list of numbers, not str")):
        with pytest.raises(ValueError, match=rf"bad\.json: {says}; it cannot be compared"):
            compare(_card(tmp_path, "bad", values), COMMITTED / "innings-v1" / "random")
    proc = _compare_cli(empty, empty)
    assert proc.returncode == 1 and proc.stderr.startswith("Error: ") and "nan" not in proc.stdout + proc.stderr


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_two_equal_constant_cards_differ_by_zero(tmp_path):
    c = compare(_card(tmp_path, "a", [3] * 100), _card(tmp_path, "b", [3] * 100))
    assert c["difference"] == 0.0 and c["ci95"] == [0.0, 0.0] and c["first_mean"] == 0.3
    proc = _compare_cli(tmp_path / "a.json", tmp_path / "b.json")
    assert proc.returncode == 0 and "= +0.00 points, paired 95 % interval [+0.00 points, +0.00 points]" in proc.stdout
    assert "nan" not in proc.stdout.lower()


def test_compare_takes_a_played_cards_scores_from_its_ledger(tmp_path):
    folder = Path(shutil.copytree(COMMITTED / "innings-v1" / "random", tmp_path / "random"))
    card = json.loads((folder / SCORECARD_JSON).read_text())
    (folder / SCORECARD_JSON).write_text(json.dumps(dict(card, values=[10] * 100)))
    with pytest.raises(ValueError, match=r"random/scorecard\.json: its values .* differs from what its ledger gives"):
        compare(folder, COMMITTED / "innings-v1" / "nearest")


def test_verify_checks_a_scorecard_against_its_ledger_as_the_board_does(tmp_path):
    """``python -m billiards.files verify`` on an evaluation folder runs the board's derivation
    (billiards.bench.run.scorecard_problems): a committed folder agrees; a claimed win rate, a
    partial flag that its ledger contradicts, or a record past the track's rules is named."""
    from billiards.files import verify

    folder = Path(shutil.copytree(COMMITTED / "match-x5-v1" / "random", tmp_path / "random"))
    assert verify(folder)[0] == []
    card = json.loads((folder / SCORECARD_JSON).read_text())
    (folder / SCORECARD_JSON).write_text(json.dumps(dict(card, match=dict(card["match"], win_rate=1.0), partial=True)))
    problems = verify(folder)[0]
    assert any("random/scorecard.json: it says partial=True, but its ledger holds 20 of the 20 units" in p for p in problems)
    assert any("random/scorecard.json: its match.win_rate (1.0) differs from what its ledger gives (0.0)" in p for p in problems)
    (folder / SCORECARD_JSON).write_text(json.dumps(card))
    forge(folder, _set("points", [12.0, 0.0]))
    assert any("unit 0 of its ledger breaks the rules of match-x5-v1: the agent's points 12.0: outside [0, 10]" in p
               for p in verify(folder)[0])
