"""What a fresh interpreter sees, where this process, which imported everything long ago, cannot
tell: what importing a module pulls in (the gymnasium path and the report without torch, a
reward model without the trainer or Hydra, billiards.device without torch), what ``import
billiards`` and a config module register on their own, and what a dependency missing from the
start makes of an evaluation. Each test starts a Python of its own: the process is the point
(docs/development.md, "Tests")."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from conftest import APP_ENV

REPO = ROOT = Path(__file__).resolve().parents[1]
ENV = APP_ENV  # train.py's environment in its tests


def ok(proc: subprocess.CompletedProcess) -> subprocess.CompletedProcess:
    assert proc.returncode == 0, f"exit {proc.returncode}\nstdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-5000:]}"
    return proc


# ----------------------------------------------------------------------------- what importing a module pulls in


def run_python(code: str) -> str:
    """Run code in a fresh interpreter on this checkout; its stdout."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


@pytest.mark.slow
def test_gym_path_imports_neither_torch_nor_torchrl_and_keeps_the_start_method():
    out = run_python("""
        import multiprocessing as mp, sys
        import gymnasium as gym
        import billiards.envs
        env = gym.make("Billiards4Ball-v0")
        env.reset(seed=0)
        env.step(env.action_space.sample())
        print(sorted(m for m in ("torch", "torchrl", "tensordict") if m in sys.modules), mp.get_start_method(allow_none=True))
    """).splitlines()
    assert out == ["[] None"]  # (the TorchRL names still load on use: every other test imports them)


@pytest.mark.slow
def test_report_loads_without_torch_or_the_simulator(tmp_path):
    """`billiards.report` (and the search tables it reads) is file work: it must not pay for
    importing torch, TorchRL or numba, so it stays instant on a loaded cluster node."""
    code = (
        "import sys, billiards.report, billiards.search.report; "
        "heavy = [m for m in ('torch', 'torchrl', 'tensordict', 'numba') if m in sys.modules]; "
        "assert not heavy, heavy; "
        "from billiards.search import H2Config; assert 'numba' in sys.modules"
    )
    ok(subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=ENV, capture_output=True, text=True, timeout=900))


def test_device_spellings_resolve_and_importing_the_module_needs_no_torch(monkeypatch):
    """``billiards.device``: ``auto`` is the CPU without a GPU and the current GPU with one,
    ``cuda:N`` must name an existing GPU, anything else is refused with the allowed spellings;
    importing it (and checking cpu / auto) leaves torch unimported."""
    import torch

    from billiards.device import device_error, resolve_device

    code = ("import sys; from billiards.device import device_error; "
            "assert device_error('cpu') is None and device_error('auto') is None; assert 'torch' not in sys.modules")
    ok(subprocess.run([sys.executable, "-c", code], cwd=REPO, env=ENV, capture_output=True, text=True, timeout=900))

    for bad in ("gpu", "CUDA", "cuda:", "cuda:x", "cpu:0", "auto:1", "", "cuda:0:1"):
        assert device_error(bad) == f"device={bad!r} is not a device: use auto, cpu, cuda or cuda:N", bad
        with pytest.raises(ValueError, match="is not a device"):
            resolve_device(bad)
    assert resolve_device("cpu") == torch.device("cpu")
    if not torch.cuda.is_available():
        assert resolve_device("auto") == torch.device("cpu")
        assert "no CUDA GPU" in device_error("cuda") and "no CUDA GPU" in device_error("cuda:0")
        with pytest.raises(ValueError, match="no CUDA GPU"):
            resolve_device("cuda")
    # a machine with two GPUs, the second one current
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setattr(torch.cuda, "current_device", lambda: 1)
    assert resolve_device("auto") == resolve_device("cuda") == torch.device("cuda", 1)
    assert resolve_device("cuda:0") == torch.device("cuda", 0) and device_error("cuda:1") is None
    assert device_error("cuda:2") == "device=cuda:2: this machine has 2 CUDA GPU(s), cuda:0 to cuda:1"


@pytest.mark.slow
def test_a_reward_model_loads_without_the_trainer_or_hydra(tmp_path):
    """What a process imports to load a reward model (the env's rm bonus does): no billiards.rl,
    no Hydra, no OmegaConf."""
    code = (
        "import sys\n"
        "from billiards.rm import RewardModel, load_model, save_model\n"
        f"path = save_model({str(tmp_path / 'rm.pt')!r}, RewardModel(hidden=(4,)))\n"
        "load_model(path)\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('hydra', 'omegaconf') or m.startswith('billiards.rl'))\n"
        "print('IMPORTED', bad)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "IMPORTED []" in proc.stdout, proc.stdout


# ----------------------------------------------------------------------------- what an import registers


@pytest.mark.slow
def test_import_billiards_registers_the_gymnasium_env_and_the_module_prefix_works():
    """``gym.make("billiards:Billiards4Ball-v0")`` in a fresh interpreter, with no import of ours,
    and ``import billiards`` alone registering the ID, without loading torch."""
    code = ("import sys, gymnasium as gym\n"
            "env = gym.make('billiards:Billiards4Ball-v0')\n"
            "obs, _ = env.reset(seed=0)\n"
            "assert obs.shape == (28,), obs.shape\n"
            "import billiards\n"
            "assert billiards.GYM_ID in gym.registry\n"
            "print('TORCH', 'torch' in sys.modules)\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "TORCH False" in proc.stdout


@pytest.mark.slow
def test_registration_is_the_same_idiom_in_a_fresh_process():
    """A fresh process that imports only billiards.search.config can compose search.py's config
    (and only billiards.rl.config, train.py's): nothing else has to be called."""
    for module, name in (("billiards.search.config", "search"), ("billiards.rl.config", "config")):
        code = (f"import {module}\n"
                "from hydra import compose, initialize_config_dir\n"
                f"with initialize_config_dir(config_dir={str(REPO / 'conf')!r}, version_base='1.3'):\n"
                f"    print('SEED', compose({name!r}).seed)\n")
        proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=900)
        assert proc.returncode == 0 and "SEED 0" in proc.stdout, proc.stderr[-2000:]


# ----------------------------------------------------------------------------- a dependency missing from the start


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_a_missing_dependency_of_the_package_is_named_with_its_install_not_put_on_the_agent():
    """In a fresh interpreter without pettingzoo (a dependency every match plays through)."""
    code = ("import sys\nsys.modules['pettingzoo'] = None  # as if not installed\n"
            "import billiards.bench as bench\n"
            "try:\n    bench.evaluate('random', 'match-x5-v1', limit=1, progress=False)\n"
            "except bench.EvaluationError as err:\n    print(err)\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    msg = proc.stdout.strip()
    assert msg.startswith("the evaluation cannot play match 0 of match-x5-v1: it needs pettingzoo, which is not installed"), msg
    assert 'install it: pip install "pettingzoo' in msg and "Not a failure of agent random" in msg
    assert "agent random failed" not in msg


@pytest.mark.slow
def test_human_render_mode_listed_only_with_its_renderer_and_the_checker_passes_without_it():
    """gymnasium's checker opens one env per listed render mode: on the default install (no
    pygame) "human" is not listed, so check_env passes; where pygame imports it is listed."""
    code = (
        "import sys, warnings; sys.modules['pygame'] = None\n"
        "import importlib.util; importlib.util.find_spec = (lambda f: lambda name, *a: None if name == 'pygame' else f(name, *a))"
        "(importlib.util.find_spec)\n"
        "import gymnasium as gym; from gymnasium.utils.env_checker import check_env\n"
        "from billiards.envs import GYM_ID, Billiards4BallInningEnv\n"
        "assert Billiards4BallInningEnv.metadata['render_modes'] == ['rgb_array'], Billiards4BallInningEnv.metadata\n"
        "warnings.simplefilter('ignore'); check_env(gym.make(GYM_ID).unwrapped); print('ok')\n"
    )
    assert run_python(code).strip().endswith("ok")
    from billiards.envs import Billiards4BallInningEnv

    has = importlib.util.find_spec("pygame") is not None
    assert ("human" in Billiards4BallInningEnv.metadata["render_modes"]) == has
