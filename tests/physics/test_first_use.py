"""The simulator's first use on a machine: it says so before it compiles, once, and compiles
each kernel once (billiards.physics.first_use, billiards.physics.core's "Compile time"); the
warm-up looks for the kernels where numba caches them. A fresh process (its numba cache given
by NUMBA_CACHE_DIR, read when numba starts) is the point of the tests that start one."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from billiards.physics import canonical_rack, core, first_use, simulate_batch, simulate_shot

RACK = canonical_rack()
ACTION = np.array([0.3, 0.5, 0.1, -0.2])


def said(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(("compiling", "simulator ready"))]


def test_a_kernel_whose_first_call_compiles_says_so_once(monkeypatch, capsys):
    """The API prepares each entry kernel's first call in a process (first_use.CHECKED): when it
    would compile, a notice with the expected time goes to stderr before, and the time it took
    after; every later call is silent, and the results are those of a plain call."""
    single = simulate_batch(RACK[None], ACTION[None])
    shot = simulate_shot(RACK, ACTION)
    monkeypatch.setattr(first_use, "CHECKED", set())  # a process that has not called a kernel yet
    monkeypatch.setattr(first_use, "will_compile", lambda kernel: True)  # ... and has no cache
    capsys.readouterr()
    again = [simulate_batch(RACK[None], ACTION[None]) for _ in range(3)]
    lines = said(capsys.readouterr().err)
    assert len(lines) == 2, lines
    assert lines[0] == f"compiling the simulator (first use on this machine: about {first_use.FIRST_SECONDS} s on two cores; " \
                       "cached for every later run) ..."
    assert lines[1].startswith("simulator ready: compiled in ") and str(first_use.CACHE_DIR) in lines[1]
    assert first_use.CHECKED == {core.run_batch_serial}
    for res in again:
        assert res.positions.tobytes() == single.positions.tobytes() and res.n_events.tolist() == single.n_events.tolist()
    # another entry kernel says so once too; a batch on the one already prepared says nothing
    for _ in range(2):
        res = simulate_shot(RACK, ACTION)
        simulate_batch(RACK[None], ACTION[None])
    lines = said(capsys.readouterr().err)
    assert len(lines) == 2 and lines[0].startswith("compiling the simulator"), lines
    assert res.event_state.tobytes() == shot.event_state.tobytes()
    assert first_use.CHECKED == {core.run_batch_serial, core.checked_shot}


def test_loaded_or_cached_kernels_say_nothing(monkeypatch, capsys):
    simulate_batch(RACK[None], ACTION[None])
    monkeypatch.setattr(first_use, "CHECKED", set())
    capsys.readouterr()
    simulate_batch(RACK[None], ACTION[None])
    simulate_shot(RACK, ACTION)
    assert capsys.readouterr().err == ""
    assert {core.run_batch_serial, core.checked_shot} <= first_use.CHECKED
    assert not first_use.will_compile(core.run_batch_serial)  # loaded in this process


def test_the_notice_states_the_expected_time_of_what_compiles(monkeypatch):
    """The whole simulator (the event loop not cached yet) is announced with FIRST_SECONDS, a
    further entry kernel alone with MORE_SECONDS and its name."""
    lines, compiled = [], []

    class Kernel:  # an entry kernel of core that has not been compiled
        overloads: dict = {}
        py_func = core.run_batch.py_func

        def compile(self, sig):
            compiled.append(sig)

    kernel = Kernel()
    monkeypatch.setattr(first_use, "CHECKED", set())
    monkeypatch.setattr(first_use, "_in_cache", lambda k: False)
    monkeypatch.setattr(core, "run_shot", Kernel())  # the event loop: neither loaded nor cached
    first_use.before_first_call(kernel, np.zeros((2, 4, 2)), 1.5, log=lines.append)
    assert lines[0].startswith(f"compiling the simulator (first use on this machine: about {first_use.FIRST_SECONDS} s")
    assert lines[1].startswith("simulator ready") and kernel in first_use.CHECKED
    assert [str(s) for s in compiled[0]] == ["array(float64, 3d, C)", "float64"]  # the call's own types
    first_use.before_first_call(kernel, np.zeros((2, 4, 2)), 1.5, log=lines.append)
    assert len(lines) == 2 and len(compiled) == 1  # prepared once per process
    monkeypatch.setattr(core.run_shot, "overloads", {"loaded": None}, raising=False)  # the event loop is here
    lines.clear()
    first_use.CHECKED.clear()  # another process
    first_use.before_first_call(kernel, np.zeros((2, 4, 2)), 1.5, log=lines.append)
    assert lines[0].startswith(f"compiling the simulator's parallel batch kernel (first use on this machine: "
                               f"about {first_use.MORE_SECONDS} s")


FIRST_USE = """
import json, sys
import numpy as np
from numba.core.registry import CPUDispatcher
from billiards.physics import canonical_rack, core, simulate_batch, simulate_shot
rack, action = canonical_rack(), np.array([0.3, 0.5, 0.1, -0.2])
for step in ("batch", "batch again", "shot", "parallel"):
    print(f"[{step}]", file=sys.stderr, flush=True)
    if step == "shot":
        simulate_shot(rack, action)
    else:
        n = 64 if step == "parallel" else 1
        simulate_batch(np.repeat(rack[None], n, axis=0), np.repeat(action[None], n, axis=0))
print(json.dumps({name: len(k.signatures) for name, k in vars(core).items() if isinstance(k, CPUDispatcher) and k.signatures}))
"""


@pytest.mark.slow
def test_the_first_use_on_a_machine_says_so_before_it_compiles(tmp_path):
    """A fresh numba cache: the first batch says it compiles the simulator, with the expected
    time, before it does, and how long it took; a second batch says nothing; the single shot and
    the parallel batch, compiled next, say so for themselves; every kernel compiled once (the
    event loop and _halt twice: with and without the log). The same cache in a new process:
    not a word."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    first = subprocess.run([sys.executable, "-c", FIRST_USE], env=env, capture_output=True, text=True, check=True, timeout=600)
    lines = [line for line in first.stderr.splitlines() if line.startswith(("[", "compiling", "simulator ready"))]
    assert lines[:4] == [
        "[batch]",
        f"compiling the simulator (first use on this machine: about {first_use.FIRST_SECONDS} s on two cores; "
        "cached for every later run) ...",
        lines[2], "[batch again]"], first.stderr
    assert lines[2].startswith("simulator ready: compiled in ") and str(tmp_path) in lines[2]
    assert lines[4] == "[shot]" and lines[5].startswith("compiling the simulator's single-shot kernel (first use on this machine: ")
    assert lines[7] == "[parallel]" and lines[8].startswith("compiling the simulator's parallel batch kernel (first use on this machine: ")
    assert lines[6].startswith("simulator ready") and lines[9].startswith("simulator ready") and len(lines) == 10
    compiled = json.loads(first.stdout.splitlines()[-1])
    twice = {name for name, n in compiled.items() if n > 1}
    assert twice == {"run_shot", "_halt"} and compiled["run_shot"] == 2 and compiled["_halt"] == 2, compiled
    assert {"checked_shot", "run_batch_serial", "run_batch", "_record", "_clear", "resolve_transition"} <= compiled.keys()

    cached = subprocess.run([sys.executable, "-c", FIRST_USE], env=env, capture_output=True, text=True, check=True, timeout=600)
    assert "compiling" not in cached.stderr and "simulator ready" not in cached.stderr, cached.stderr
    loaded = {"checked_shot", "run_batch_serial", "run_batch", "check_actions", "check_positions"}  # the API's kernels
    assert json.loads(cached.stdout.splitlines()[-1]) == dict.fromkeys(loaded, 1)  # loaded, nothing compiled


def test_the_warm_up_looks_for_the_kernels_where_numba_caches_them(tmp_path):
    """Under NUMBA_CACHE_DIR numba caches the kernels there, not in the package: the warm-up
    looks there too (an empty folder: not compiled yet, so it says it will compile)."""
    import os
    import subprocess
    import sys

    probe = "from billiards.physics import warmup; print(warmup.CACHE_DIR); print(warmup.kernels_cached())"
    out = subprocess.run([sys.executable, "-c", probe], env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)},
                         capture_output=True, text=True, check=True).stdout.split()
    assert out[0].startswith(str(tmp_path)) and out[1] == "False"
