"""Submissions you can trust (issue #57): what a run folder holds is read by one reader, written
by one writer, and its ledgers are all known to ``verify``.

* One reader (``billiards.files.open_run_file``, ``read_run_bytes``, ``read_run_json``): a link
  (to a secret outside the folder), a FIFO, a directory, a file past its size bound or JSON
  nested past its depth bound is refused unread, with a sentence naming the file and never its
  content; ``verify``, the ledgers, the league's and the search's resume read through it.
* One writer (``billiards.files.run_lock``): a second writer is refused at once, naming the
  first; a dead writer's lock is taken over with a note; the lock file is nobody's run.
* Every ledger kind registered (``register_ledger``, ``ledger_kinds``), so ``verify`` knows the
  benchmark's ``units.jsonl`` too.
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from billiards import files
from billiards.files import (CHAINS, LOCK_FILE, RUN_KEY, LedgerError, LedgerKind, RunFileError, RunLockedError, append_record,
                             read_ledger, read_run_bytes, read_run_json, register_ledger, run_lock, sealed_record)

ROOT = Path(__file__).resolve().parents[1]
SECRET = "TOP-SECRET-7f3a: aws_secret_access_key=wJalrXUtnFEMI"
needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


def promptly(fn, seconds: float = 30.0):
    """``fn()``'s result, or a failure if it has not returned within ``seconds`` (a read that
    blocks on a FIFO would hang the test otherwise: it runs in a daemon thread)."""
    out: dict = {}

    def call() -> None:
        try:
            out["value"] = fn()
        except BaseException as err:  # handed to the test
            out["error"] = err

    t = threading.Thread(target=call, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), f"still blocked after {seconds} s"
    if "error" in out:
        raise out["error"]
    return out["value"]


def verify_cli(run_dir: Path, timeout: float = 120) -> subprocess.CompletedProcess:
    """``python -m billiards.files verify RUN_DIR`` in its own process, killed past ``timeout``."""
    return subprocess.run([sys.executable, "-m", "billiards.files", "verify", str(run_dir)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT)


def chain(seed: int, length: int = 3) -> dict:
    return {"seed": seed, "length": length, "decisions": length + 1, "seconds": 0.5, "last_shots": []}


def p3_folder(d: Path, lengths=(3, 5)) -> Path:
    """A finished P3 run folder as the search writes it: a sealed ledger and its results.json."""
    d.mkdir(parents=True, exist_ok=True)
    for seed, n in enumerate(lengths):
        append_record(d / "chains.jsonl", chain(seed, n), "0123456789abcdef")
    mean = sum(lengths) / len(lengths)
    (d / "results.json").write_text(json.dumps({"protocol": "p3", "values": list(lengths), "mean": mean,
                                                "extra": {"seeds": list(range(len(lengths)))}, RUN_KEY: "0123456789abcdef"}))
    return d


@pytest.fixture
def secret(tmp_path) -> Path:
    path = tmp_path / "outside" / "credentials"
    path.parent.mkdir()
    path.write_text("\n".join([SECRET, f"{SECRET} line 2", "[[[" + SECRET]) + "\n")
    return path


# ----------------------------------------------------------------------------- one reader


def test_a_symlinked_ledger_or_summary_leading_outside_is_refused_and_never_printed(tmp_path, secret, capsys):
    """The issue's case: a pull request's run folder whose ledger is a link to a secret. verify,
    the ledger reader, the benchmark's ledger reader and an append all refuse it by name; not one
    byte of the secret is printed, and nothing is written through the link."""
    run = p3_folder(tmp_path / "run")
    (run / "chains.jsonl").unlink()
    (run / "chains.jsonl").symlink_to(secret)
    assert files.main(["verify", str(run)]) == 1
    out = capsys.readouterr().out
    assert "chains.jsonl is a symbolic link, not a regular file" in out and "nothing was read" in out
    assert "TOP-SECRET" not in out and "wJalr" not in out
    with pytest.raises(LedgerError, match="chains.jsonl is a symbolic link") as err:
        read_ledger(run / "chains.jsonl", CHAINS)
    assert "SECRET" not in str(err.value)
    before = secret.read_bytes()
    with pytest.raises(LedgerError, match="chains.jsonl is a symbolic link: a ledger is written only as a regular file"):
        append_record(run / "chains.jsonl", chain(2), "0123456789abcdef")
    assert secret.read_bytes() == before
    from billiards.bench.run import EvaluationError, read_ledger as bench_ledger  # the leaderboard's ledger reader

    (run / "units.jsonl").symlink_to(secret)
    with pytest.raises(EvaluationError, match="units.jsonl is a symbolic link") as err:
        bench_ledger(run / "units.jsonl", "0123456789abcdef", repair=False)
    assert "SECRET" not in str(err.value)
    # the summary as a link, and a link to a folder: the same
    (run / "chains.jsonl").unlink()
    (run / "units.jsonl").unlink()
    append_record(run / "chains.jsonl", chain(0), "0123456789abcdef")
    (run / "results.json").unlink()
    (run / "results.json").symlink_to(secret)
    problems, _ = files.verify(run)
    assert any("results.json is a symbolic link" in p for p in problems) and not any("SECRET" in p for p in problems)
    with pytest.raises(RunFileError, match="is a symbolic link"):
        read_run_json(run / "results.json")


def test_a_link_inside_the_run_folder_to_its_own_file_is_refused_too(tmp_path):
    """No link is followed, wherever it leads: the reader does not resolve links to judge them."""
    run = p3_folder(tmp_path / "run")
    (run / "copy.json").symlink_to(run / "results.json")
    with pytest.raises(RunFileError, match="copy.json is a symbolic link"):
        read_run_json(run / "copy.json")


def test_a_linked_hydra_folder_is_refused_by_the_league_resume(tmp_path, secret):
    """Files below a run folder (a league's .hydra/config.yaml) are read only if no folder on the
    way is a link."""
    from omegaconf import OmegaConf

    from billiards.league import league_settings

    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "config.yaml").write_text(f"players: [a, b]\nnote: {SECRET}\n")
    run = tmp_path / "league"
    run.mkdir()
    (run / ".hydra").symlink_to(outside, target_is_directory=True)
    with pytest.raises(ValueError, match=r"\.hydra is a symbolic link") as err:
        league_settings(OmegaConf.create({"resume": str(run)}))
    assert "SECRET" not in str(err.value)
    with pytest.raises(RunFileError, match="lies outside its run folder"):
        read_run_bytes(outside / "config.yaml", within=run)


def test_a_bad_ledger_line_is_named_never_quoted(tmp_path, capsys):
    """The reader used to echo the first 60 bytes of a line that is not JSON, and a record's
    values: a line holding a secret is now named by its line number and what it is."""
    run = p3_folder(tmp_path / "run")
    with open(run / "chains.jsonl", "a") as f:
        f.write(SECRET + "\n")
        f.write(json.dumps(SECRET) + "\n")
        f.write(json.dumps(sealed_record({**chain(7), "length": SECRET, RUN_KEY: "0123456789abcdef"})) + "\n")
        f.write(json.dumps(sealed_record({**chain(8), RUN_KEY: SECRET})) + "\n")
    assert files.main(["verify", str(run)]) == 1
    out = capsys.readouterr().out
    assert "line 3 is not an intact P3 chain record: it is not JSON (Expecting value at column 1)" in out
    assert "line 4 is not an intact P3 chain record: it is a JSON string, not a record (an object)" in out
    assert "line 5 is not an intact P3 chain record: length must be an integer >= 0, got a string" in out
    assert "line 6 belongs to another run (run an identity that is no 16-digit hash" in out
    assert "SECRET" not in out and "wJalr" not in out


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
@needs_fifo
def test_a_fifo_in_place_of_a_run_file_is_refused_at_once(tmp_path):
    """A named pipe for results.json (or the ledger) used to block verify forever: refused
    without being opened, in its own process under a timeout."""
    run = p3_folder(tmp_path / "run")
    (run / "results.json").unlink()
    os.mkfifo(run / "results.json")
    proc = verify_cli(run)
    assert proc.returncode == 1, proc.stderr
    assert "results.json is a named pipe (FIFO), not a regular file" in proc.stdout and "Traceback" not in proc.stderr
    (run / "chains.jsonl").unlink()
    os.mkfifo(run / "chains.jsonl")
    problems, _ = promptly(lambda: files.verify(run))
    assert any("chains.jsonl is a named pipe (FIFO)" in p for p in problems)
    with pytest.raises(LedgerError, match=r"chains.jsonl is a named pipe \(FIFO\)"):
        promptly(lambda: read_ledger(run / "chains.jsonl", CHAINS))
    with pytest.raises(LedgerError, match=r"is not a regular file|is a named pipe"):
        promptly(lambda: append_record(run / "chains.jsonl", chain(9), "0123456789abcdef"))


@needs_fifo
def test_a_fifo_config_does_not_block_a_search_resume(tmp_path):
    """The directory check reads a search's config.yaml before a resume: a FIFO there is a
    sentence naming it, not a hang."""
    from billiards.search import run as search_run

    run = tmp_path / "run"
    run.mkdir()
    os.mkfifo(run / "config.yaml")
    with pytest.raises(ValueError, match=r"config.yaml is a named pipe \(FIFO\)"):
        promptly(lambda: search_run.resume_state(run, None, True))
    with pytest.raises(RunFileError, match="named pipe"):
        promptly(lambda: search_run.search_identity(run))


def test_a_directory_in_place_of_a_run_file_is_refused(tmp_path):
    run = p3_folder(tmp_path / "run")
    (run / "results.json").unlink()
    (run / "results.json").mkdir()
    problems, _ = files.verify(run)
    assert any("results.json is a directory, not a regular file" in p for p in problems)


def test_json_nested_100000_deep_is_a_sentence_not_a_recursion_error(tmp_path, capsys):
    run = p3_folder(tmp_path / "run")
    for text, why in (("[" * 100_000 + "]" * 100_000, "it nests deeper than 64 levels"),
                      ('{"a":' * 100_000 + "1" + "}" * 100_000, "it nests deeper than 64 levels"),
                      ("[" * 100_000, "its brackets do not balance")):
        (run / "results.json").write_text(text)
        with pytest.raises(RunFileError, match=r"results.json is not JSON the package reads: " + why):
            read_run_json(run / "results.json")
        assert files.main(["verify", str(run)]) == 1
        assert f"results.json is not JSON the package reads: {why}" in capsys.readouterr().out
    # 64 levels read; brackets inside strings do not count
    (run / "results.json").write_text("[" * 64 + json.dumps("]]]]{{{{" * 50) + "]" * 64)
    assert read_run_json(run / "results.json") is not None
    assert files.json_depth_problem('{"a": "[[[[[["}', limit=1) is None


def test_a_file_past_its_bound_is_refused_unread(tmp_path):
    """Each kind of run file has a documented bound (files.RUN_FILE_LIMITS); a (sparse) file past
    it is refused by its size, before a byte is read."""
    run = p3_folder(tmp_path / "run")
    for name, kind in (("results.json", "summary"), ("chains.jsonl", "ledger")):
        with open(run / name, "r+b") as f:
            f.truncate(files.RUN_FILE_LIMITS[kind] + 1)
        with pytest.raises(RunFileError, match=rf"{name} is {files.RUN_FILE_LIMITS[kind] + 1:,} bytes; a {kind} file "
                                               rf"of a run folder holds at most {files.RUN_FILE_LIMITS[kind]:,}"):
            read_run_bytes(run / name)
    problems, _ = files.verify(run)
    assert sum("bytes; a" in p and "refused unread" in p for p in problems) == 2
    assert files.run_file_kind("x/config.yaml") == "config" and files.run_file_kind("checkpoint.pt") == "checkpoint"


def test_atomic_writes_never_write_through_a_link_at_the_temporary_name(tmp_path, secret):
    before = secret.read_bytes()
    (tmp_path / "results.json.tmp").symlink_to(secret)
    files.atomic_write_text(tmp_path / "results.json", "{}\n")
    assert secret.read_bytes() == before and (tmp_path / "results.json").read_text() == "{}\n"
    assert not (tmp_path / "results.json.tmp").exists()


# ----------------------------------------------------------------------------- one writer

HOLD = """
import sys, time
from billiards.files import run_lock
with run_lock(sys.argv[1], command="python search.py resume=" + sys.argv[1], say=None):
    print("held", flush=True)
    time.sleep(600)
"""


@pytest.fixture
def holder(tmp_path):
    """A process holding tmp_path/run's lock (killed at the end)."""
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(run)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "held"
        yield run, proc
    finally:
        proc.kill()
        proc.wait()


def test_a_second_writer_is_refused_at_once_naming_the_holder(holder):
    run, proc = holder
    with pytest.raises(RunLockedError) as err:
        promptly(lambda: run_lock(run).__enter__(), 10)
    said = str(err.value)
    assert said.startswith(f"{files.display_path(run)} is being written by another run (pid {proc.pid} on "
                           f"{socket.gethostname()}, started ")
    assert "python search.py resume=" in said and "one writer per run folder" in said
    assert json.loads((run / LOCK_FILE).read_text())["pid"] == proc.pid  # the holder's record is untouched
    assert files.lock_holder(run).pid == proc.pid


def test_the_search_league_and_training_refuse_a_folder_another_run_writes(holder, capsys):
    """Each app takes the lock before it writes a byte into the folder: refused with one
    sentence naming the holder, the folder as the holder left it."""
    run, proc = holder
    from billiards.search import run as search_run
    from billiards.search.config import search_config

    cfg = search_config(protocol="p3")
    cfg.protocol.seeds, cfg.protocol.cap, cfg.progress, cfg.picture = 1, 2, False, False
    with pytest.raises(SystemExit, match=rf"^Error: .* is being written by another run \(pid {proc.pid} on "):
        search_run.run(cfg, run)
    assert sorted(p.name for p in run.iterdir()) == [LOCK_FILE]

    pytest.importorskip("pettingzoo")
    from billiards.league.players import RandomPlayer, make_agent
    from billiards.league.play import run_league
    from billiards.physics import DEFAULT_PARAMS
    from billiards.physics.noise import get_noise

    players = {n: make_agent(RandomPlayer(), get_noise("none"), DEFAULT_PARAMS) for n in ("r1", "r2")}
    with pytest.raises(RunLockedError, match=rf"being written by another run \(pid {proc.pid} "):
        run_league(players, out_dir=run, matches=1, seed=0, noise_name="none", record={}, progress=False, target=1,
                   max_innings=2)
    assert sorted(p.name for p in run.iterdir()) == [LOCK_FILE]


@pytest.mark.slow
def test_training_refuses_a_folder_another_run_writes(holder):
    from hydra import compose, initialize_config_dir

    from billiards.rl.train import train

    run, proc = holder
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base=None):
        cfg = compose("config")
    with pytest.raises(SystemExit, match=rf"^Error: .* is being written by another run \(pid {proc.pid} on "):
        train(cfg, run)
    assert sorted(p.name for p in run.iterdir()) == [LOCK_FILE]


def test_a_dead_holders_lock_is_taken_over_with_a_note(tmp_path):
    """A run killed while it wrote leaves its lock file; no process holds its flock any more,
    so the next writer takes it over, says whose it was, and removes it when done."""
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(run)], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert json.loads((run / LOCK_FILE).read_text())["pid"] == proc.pid  # left behind
    assert files.lock_holder(run) is None  # its process is gone
    said: list[str] = []
    with run_lock(run, command="python match.py resume=run", say=said.append) as lock:
        assert lock.took_over.pid == proc.pid
        assert json.loads((run / LOCK_FILE).read_text())["pid"] == os.getpid()
    assert len(said) == 1 and said[0].startswith(f"note: {files.display_path(run)}: took over the lock of a run that is "
                                                 f"no longer running (pid {proc.pid} on ")
    assert not (run / LOCK_FILE).exists()
    with run_lock(run, say=said.append) as lock:  # a lock let go in order leaves nothing to take over
        assert lock.took_over is None
    assert len(said) == 1


def test_without_flock_the_recorded_pid_decides(tmp_path, monkeypatch):
    """Where flock is missing, a lock naming a pid that is gone on this host is taken over; one
    naming a live pid here, or any pid on another host, is refused."""
    monkeypatch.setattr(files.lock, "_flock", lambda fd: None)  # where run_lock reads it
    run = tmp_path / "run"
    run.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    host = socket.gethostname()
    for pid, where, taken in ((dead.pid, host, True), (os.getppid(), host, False), (dead.pid, "elsewhere.example", False)):
        (run / LOCK_FILE).write_text(json.dumps({"pid": pid, "host": where, "started": "then", "command": "python train.py"}))
        if taken:
            with run_lock(run, say=None) as lock:
                assert lock.took_over.pid == pid
        else:
            with pytest.raises(RunLockedError, match=rf"another run \(pid {pid} on {where}, started then: python train.py\)"):
                run_lock(run, say=None).__enter__()


def test_the_lock_file_is_refused_as_a_link_and_belongs_to_no_run(tmp_path, secret):
    from billiards.app_config.rundirs import _held

    run = tmp_path / "run"
    run.mkdir()
    (run / LOCK_FILE).symlink_to(secret)
    with pytest.raises(RunLockedError, match=r"\.lock is not a regular file"):
        run_lock(run).__enter__()
    (run / LOCK_FILE).unlink()
    # a lock file left by a killed run: alone it makes the folder no one's (empty), beside a run it is that run's
    (run / LOCK_FILE).write_text("{}")
    assert _held(run) is None
    p3_folder(run)
    held = _held(run)
    assert held.kind is not None and held.kind.app == "search.py" and LOCK_FILE not in held.names
    assert files.verify(run)[0] == []


# ----------------------------------------------------------------------------- every ledger kind


def _thing_problem(rec: dict) -> str | None:
    return None if isinstance(rec.get("k"), int) and isinstance(rec.get("v"), int) else "k and v must be integers"


def _thing_summary(records: list[dict], summary: dict, name: str) -> list[str]:
    total = sum(r["v"] for r in records)
    return [] if summary.get("total") == total else [f"{name}'s total is not its records' ({total})"]


def test_verify_knows_every_registered_ledger_kind(tmp_path, monkeypatch, capsys):
    """A kind registered beside chains and matches (as the benchmark's units.jsonl is) is
    verified like them: its records, its seal and run identity, its summary by the kind's check."""
    monkeypatch.setattr(files.ledgers, "_KINDS", dict(files.ledgers._KINDS))  # the registry register_ledger fills
    run = tmp_path / "run"
    run.mkdir()
    for k in range(3):
        append_record(run / "things.jsonl", {"k": k, "v": 10 * k}, "fedcba9876543210")
    (run / "things.json").write_text(json.dumps({"total": 30, RUN_KEY: "fedcba9876543210"}))
    assert files.verify(run)[0] == [f"{files.display_path(run)}: no ledger "
                                    f"({' or '.join(k.file for k in files.ledger_kinds())}) there"]
    kind = register_ledger(LedgerKind("things.jsonl", "thing record", lambda r: r["k"], lambda r: f"thing {r['k']}",
                                      _thing_problem, "things.json", _thing_summary))
    assert kind in files.ledger_kinds()
    assert files.main(["verify", str(run)]) == 0
    assert "things.jsonl: 3 sealed records of run 'fedcba9876543210'" in capsys.readouterr().out
    (run / "things.json").write_text(json.dumps({"total": 31, RUN_KEY: "fedcba9876543210"}))
    with open(run / "things.jsonl", "a") as f:
        f.write(json.dumps(sealed_record({"k": 1, "v": 5, RUN_KEY: "fedcba9876543210"})) + "\n")
    problems, _ = files.verify(run)
    assert any("things.jsonl: line 4 repeats thing 1, already finished on line 2" in p for p in problems)
    assert any("things.json's total is not its records' (30)" in p for p in problems)
    with pytest.raises(ValueError, match="things.jsonl is the ledger of thing records already"):
        register_ledger(LedgerKind("things.jsonl", "other record", lambda r: r, str, _thing_problem, "x.json"))
    # a check named "module:function" is loaded when a summary is checked; one that cannot be is a problem
    register_ledger(LedgerKind("things.jsonl", "thing record", lambda r: r["k"], lambda r: f"thing {r['k']}",
                               _thing_problem, "things.json", "billiards.no_such_module:check"))
    assert any("cannot be checked against its ledger" in p for p in files.verify(run)[0])


def test_the_benchmarks_ledger_is_verified(tmp_path):
    """units.jsonl (billiards.bench.run's UNITS, named in files.LEDGER_PROVIDERS) is known to
    verify: a committed evaluation folder verifies; an edited unit is caught by line."""
    import shutil

    assert "units.jsonl" in [k.file for k in files.ledger_kinds()]
    source = next(p.parent for p in sorted((ROOT / "results").rglob("units.jsonl")))
    problems, notes = files.verify(source)
    assert problems == [] and any("units.jsonl:" in n and "records" in n for n in notes)
    run = tmp_path / "eval"
    shutil.copytree(source, run)
    lines = (run / "units.jsonl").read_text().splitlines()
    rec = json.loads(lines[0])
    rec["cpu_s"] = rec["cpu_s"] + 1
    (run / "units.jsonl").write_text("\n".join([json.dumps(rec), *lines[1:]]) + "\n")
    problems, _ = files.verify(run)
    assert any("units.jsonl: line 1 is not an intact evaluation unit record: its content does not match its seal" in p
               for p in problems)
