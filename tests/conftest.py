"""Fixtures shared by several test modules, and a patient ``subprocess.Popen``."""

import os
import subprocess
import time
from pathlib import Path

import pytest

_popen_init = subprocess.Popen.__init__


def _patient_popen_init(self, *args, **kwargs):
    """On a loaded machine (CI beside training jobs, many threads) the kernel may refuse a fork
    for a moment (EAGAIN, ``BlockingIOError``): try again with a back-off before failing. Every
    test that starts a process (the apps, the campaign runner's children) goes through here."""
    for attempt in range(6):
        try:
            return _popen_init(self, *args, **kwargs)
        except BlockingIOError:
            time.sleep(0.25 * 2 ** attempt)
    return _popen_init(self, *args, **kwargs)


subprocess.Popen.__init__ = _patient_popen_init


def _record_processes(log: str) -> None:
    """With ``SAGU_PROCESS_LOG=<file>`` set, every process a test starts (``subprocess``,
    ``multiprocessing``, a fork) appends the test's id to that file: how the suite counts the
    test files that start processes (docs/development.md)."""
    import _posixsubprocess

    def note():
        test = os.environ.get("PYTEST_CURRENT_TEST")
        if test:
            with open(log, "a") as f:
                f.write(test.rsplit(" ", 1)[0] + "\n")

    fork_exec, fork = _posixsubprocess.fork_exec, os.fork

    def noting_fork_exec(*args, **kwargs):
        note()
        return fork_exec(*args, **kwargs)

    def noting_fork():
        note()
        return fork()

    _posixsubprocess.fork_exec = subprocess._fork_exec = noting_fork_exec  # multiprocessing's, subprocess's
    os.fork = noting_fork


if os.environ.get("SAGU_PROCESS_LOG"):
    _record_processes(os.environ["SAGU_PROCESS_LOG"])


def _once_per_process() -> None:
    """What a process starts once, for whichever test comes first, started here before any test:
    so that the process log (SAGU_PROCESS_LOG) names the tests that start processes of their own,
    in whatever order pytest-xdist deals the tests out.

    * The commit a run records (``billiards.provenance.git_commit``: ``git rev-parse`` and
      ``git status``, two processes for each record) is read once, here: every record of the
      session names the commit and the ``+dirty`` of the session's start.
    * ``uname -p``: ``platform`` asks it once per process, when h5py is first imported (tensordict
      imports it lazily).
    * multiprocessing's resource tracker: once TorchRL has made ``spawn`` the start method, the
      first semaphore (a replay buffer's counters, tqdm's lock) starts it."""
    import platform
    from multiprocessing import resource_tracker

    import billiards.provenance as provenance

    answers: dict[tuple, subprocess.CompletedProcess] = {}

    def run_once(cmd, **kwargs):
        if tuple(cmd) not in answers:
            answers[tuple(cmd)] = subprocess.run(cmd, **kwargs)
        return answers[tuple(cmd)]

    provenance.subprocess = type("GitOnce", (), {"run": staticmethod(run_once)})  # the module's only use: git_commit
    provenance.git_commit()
    platform.processor()
    resource_tracker.ensure_running()


def pytest_configure(config):
    """Under pytest-xdist (``-n N``) the controller compiles the simulator once before the workers
    start, so that they load its kernels from numba's cache instead of all compiling at once. A
    process that runs tests starts what it starts once (:func:`_once_per_process`)."""
    if getattr(config.option, "numprocesses", None) and not hasattr(config, "workerinput"):
        from billiards.physics.warmup import warm_up

        warm_up(log=lambda message: None)
    else:
        _once_per_process()


REPO = Path(__file__).resolve().parents[1]
SHIPPED_BASE = REPO / "results" / "policies" / "base" / "seed0.pt"
# the environment of an app's run in the tests (train.py, the report, a fresh interpreter): one
# thread, wandb offline and quiet, Hydra's short errors
APP_ENV = {**os.environ, "WANDB_MODE": "offline", "WANDB_SILENT": "true", "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1",
           "HYDRA_FULL_ERROR": "0"}


@pytest.fixture
def recorded(monkeypatch):
    """Every (start tables, played actions) batch the noise-aware searches (robust, noisy PUCT)
    simulate, in order; the searches still simulate them."""
    import numpy as np

    import billiards.search.puct_noise as puct_noise_mod
    import billiards.search.robust as robust_mod
    from billiards.physics import simulate_batch

    calls = []

    def recording(positions, actions, *params):
        calls.append((np.array(positions), np.array(actions)))
        return simulate_batch(positions, actions, *params)

    monkeypatch.setattr(robust_mod, "simulate_batch", recording)
    monkeypatch.setattr(puct_noise_mod, "simulate_batch", recording)
    return calls


@pytest.fixture
def international_policy(tmp_path) -> Path:
    """The shipped ``base`` seed 0 (trained on korean_medium, the default table), saved again as
    if it had been trained on the international table: a policy from another table."""
    import torch

    from billiards.files import SEAL_KEY, save_tagged

    state = torch.load(SHIPPED_BASE, map_location="cpu", weights_only=True)
    state.pop(SEAL_KEY)
    state["config"]["physics"] = {"preset": "international"}
    return save_tagged(tmp_path / "made_on_international.pt", state)


# each app's config name and the modules its entry point imports before Hydra composes (they
# register its schemas and checks)
APP_CONFIGS = {"train.py": ("config", ("billiards.rl.config", "billiards.search.config")),
               "search.py": ("search", ("billiards.search.config",)), "match.py": ("match", ("billiards.league.config",)),
               "evaluate.py": ("evaluate", ("billiards.bench.config",))}


def refusal(app: str, *overrides: str, cwd: Path | None = None) -> str:
    """What ``python <app> <overrides>`` says when it refuses them, found in this process: the
    entry point's command-line guard, Hydra's composition (a key not in a schema, a missing
    option) and the app's validating callback, in that order -- the steps the app takes before
    Hydra writes anything. An AssertionError if the app would accept the command line.

    For a single run; a multirun's jobs (``-m``) and the guard's flags are the subprocess tests'.
    The run directory is judged relative to ``cwd`` (default: the current directory)."""
    import contextlib
    import importlib
    import os

    from hydra import compose, initialize_config_dir
    from hydra.utils import get_class

    from billiards.app_config import override_errors

    config_name, modules = APP_CONFIGS[app]
    assert "-m" not in overrides and "--multirun" not in overrides, "a multirun is the subprocess tests'"
    errors = override_errors(list(overrides))
    if errors:
        return "Error: " + "\n".join(errors)
    for module in modules:
        importlib.import_module(module)
    here = os.getcwd()
    with contextlib.ExitStack() as stack:
        if cwd is not None:
            os.chdir(cwd)
            stack.callback(os.chdir, here)
        try:
            with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
                cfg = compose(config_name, overrides=list(overrides), return_hydra_config=True)
        except Exception as err:  # what Hydra prints for a composition error, its cause included
            return "\n".join(str(e) for e in (err, err.__cause__) if e is not None)
        callback = get_class(cfg.hydra.callbacks.validate._target_)()
        try:
            callback.on_run_start(config=cfg)
        except SystemExit as err:
            return str(err.code)
    raise AssertionError(f"{app} accepts {' '.join(overrides)}")


def app_here(script: Path | str, *args: str, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    """``python <script> <args>`` (``python -m <script> <args>`` for a module's name) run in this
    process, as the command line would run it: the entry point's own ``__main__`` block (its
    command-line guard, then Hydra: composition, the validating callback, the run directory and
    its records, logging), with ``cwd`` as the working directory and ``env`` set in
    ``os.environ`` for the run. Returns what ``subprocess.run``
    would: the exit status (0, or the code the app exits with; 1 for an exception, as Hydra
    reports one) and everything written to stdout and stderr.

    For the tests where the process is not the point (a run, a resume, a refusal): it saves the
    4-6 s a fresh interpreter spends importing torch, TorchRL and Hydra. What a process holds is
    put back afterwards (working directory, environment, argv, every logger's handlers, level
    and state, torch's and numba's thread counts, torch's global generator, signal handlers,
    Hydra's global state (a context the test holds included) and the composition guard the entry point puts on Hydra's config
    loader). A multirun (its launcher's processes) and wandb (a service process of its own) get
    a process here, as a user's would; a signal, a kill and a fresh import stay the subprocess
    tests'."""
    import contextlib
    import io
    import logging
    import os
    import runpy
    import signal
    import sys
    import warnings

    import numba
    import torch
    from hydra._internal.config_loader_impl import ConfigLoaderImpl
    from hydra.core.global_hydra import GlobalHydra

    module = str(script) if not str(script).endswith(".py") else None  # python -m <module>
    script = Path(script)
    if module is None and not script.is_absolute():
        script = REPO / script
    command = ["-m", module] if module is not None else [str(script)]
    if {"-m", "--multirun", "logger=wandb"} & set(args):
        return subprocess.run([sys.executable, *command, *args], cwd=cwd, capture_output=True, text=True, timeout=900,
                              env={**os.environ, "PYTHONPATH": str(REPO), **(env or {})})
    out, err = io.StringIO(), io.StringIO()
    loggers = [logging.getLogger(), *(x for x in logging.root.manager.loggerDict.values() if isinstance(x, logging.Logger))]
    saved_logging = {logger: (list(logger.handlers), logger.level, logger.disabled, logger.propagate) for logger in loggers}
    saved = (os.getcwd(), dict(os.environ), list(sys.argv), torch.get_num_threads(), numba.get_num_threads(),
             torch.get_rng_state(), {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)},
             ConfigLoaderImpl.load_configuration)  # the entry point's guard wraps Hydra's loader (app_config)
    code: int = 0
    running = GlobalHydra.instance().hydra  # a Hydra context the test holds (compose's), put back afterwards
    GlobalHydra.instance().clear()
    try:
        os.chdir(cwd)
        env = dict(env or {})
        # numba reads NUMBA_NUM_THREADS again at every compilation and refuses a value other than
        # the one its pool started with: the process's pool keeps its size, the run gets the
        # thread count it asked for through numba.set_num_threads
        numba_wanted = env.pop("NUMBA_NUM_THREADS", None)
        os.environ.update(env)
        if numba_wanted is not None:
            numba.set_num_threads(min(int(numba_wanted), numba.config.NUMBA_NUM_THREADS))
        sys.argv = [str(script), *args]
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                if module is not None:
                    with warnings.catch_warnings():  # the module was imported before: runpy runs it afresh as __main__
                        warnings.filterwarnings("ignore", "'.*' found in sys.modules", RuntimeWarning)
                        runpy.run_module(module, run_name="__main__", alter_sys=True)
                else:
                    runpy.run_path(str(script), run_name="__main__")
            except SystemExit as stop:  # what the interpreter makes of sys.exit(x)
                if stop.code is None:
                    code = 0
                elif isinstance(stop.code, int):
                    code = stop.code
                else:
                    print(stop.code, file=sys.stderr)
                    code = 1
    finally:
        GlobalHydra.instance().clear()
        if running is not None:
            GlobalHydra.instance().initialize(running)
        cwd_was, environ, argv, torch_threads, numba_threads, rng, handlers, load_configuration = saved
        ConfigLoaderImpl.load_configuration = load_configuration
        os.chdir(cwd_was)
        os.environ.clear()
        os.environ.update(environ)
        sys.argv = argv
        torch.set_num_threads(torch_threads)
        numba.set_num_threads(numba_threads)
        torch.set_rng_state(rng)
        for num, handler in handlers.items():
            signal.signal(num, handler)
        kept = {h for handlers, *_ in saved_logging.values() for h in handlers}
        for logger in [logging.getLogger(), *logging.root.manager.loggerDict.values()]:
            if not isinstance(logger, logging.Logger):
                continue
            for handler in logger.handlers:  # what Hydra's logging opened (the run's .log file)
                if handler not in kept:
                    handler.close()
            handlers, level, disabled, propagate = saved_logging.get(logger, ([], logging.NOTSET, False, True))
            logger.handlers[:], logger.disabled, logger.propagate = handlers, disabled, propagate
            logger.setLevel(level)
    return subprocess.CompletedProcess([sys.executable, *command, *args], code, out.getvalue(), err.getvalue())
