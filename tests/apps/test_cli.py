"""The console command ``sagu`` and what the package carries: every app reachable by its name, the
scripts and the command running one app each, and every file the configs and the benchmark's own
entries name shipped in the wheel (setup.py's SHIPPED). The installed wheel itself is exercised
from outside the repository by .ci/smoke_installed.py."""

from __future__ import annotations

import ast
import importlib
import re
import runpy
import sys
from pathlib import Path

import pytest

import billiards
from billiards import cli
from billiards.apps import APPS
from billiards.files import CONF_DIR, IN_CHECKOUT, ROOT

REPO = Path(__file__).resolve().parents[2]


def shipped_patterns() -> tuple[str, ...]:
    """setup.py's SHIPPED, read without running setup.py."""
    tree = ast.parse((REPO / "setup.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "SHIPPED" for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError("setup.py defines no SHIPPED")


def shipped() -> set[str]:
    """What the wheel carries from outside billiards/: the repository's files matching SHIPPED, as setup.py globs them."""
    return {p.relative_to(REPO).as_posix() for pattern in shipped_patterns() for p in REPO.glob(pattern) if p.is_file()}


def test_a_checkout_reads_its_own_files():
    assert IN_CHECKOUT and ROOT == REPO and CONF_DIR == REPO / "conf"


def test_the_help_lists_every_app_and_the_version_is_the_packages(capsys):
    assert cli.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert billiards.__version__ in out
    for name in (*APPS, "view", "leaderboard", "render"):
        assert re.search(rf"^\s+{name}\s", out, re.M), name
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"sagu-bench {billiards.__version__}"


def test_an_unknown_command_is_refused_with_the_list(capsys):
    assert cli.main(["evaluat"]) == 2
    err = capsys.readouterr().err
    assert "unknown command 'evaluat'" in err and "evaluate" in err


def test_every_app_is_a_command_and_each_script_runs_that_app():
    assert set(APPS) <= set(cli.COMMANDS)
    for app in APPS:
        module = importlib.import_module(f"billiards.apps.{app}")
        assert cli.COMMANDS[app][0] == module.__name__
        # the repository's script holds no app of its own: running it calls the package's main
        script = runpy.run_path(str(REPO / f"{app}.py"), run_name="not_main")
        assert script["main"] is module.main


@pytest.mark.parametrize("app", APPS)
def test_a_hydra_command_takes_the_scripts_help(app, capsys, monkeypatch):
    from hydra._internal.config_loader_impl import ConfigLoaderImpl

    monkeypatch.setattr(sys, "argv", list(sys.argv))
    # the app installs its composition guard into Hydra's loader (process-wide): undone after the test
    for attr in ("load_configuration", "get_group_options"):
        monkeypatch.setattr(ConfigLoaderImpl, attr, getattr(ConfigLoaderImpl, attr))
    with pytest.raises(SystemExit) as err:
        cli.main([app, "--help"])
    assert err.value.code in (None, 0)
    out = capsys.readouterr().out
    assert f"{app}.py" in out and "== Config" in out  # the app's own help page (conf/hydra/help)


def test_the_tools_take_their_arguments(capsys):
    with pytest.raises(SystemExit) as err:
        cli.main(["leaderboard", "compare", "--help"])
    assert err.value.code == 0 and "compare [-h] [--json] first second" in capsys.readouterr().out


def test_every_file_the_configs_and_the_benchmark_name_is_shipped():
    from billiards.bench.entries import ENTRIES

    named = set()
    for path in CONF_DIR.rglob("*.yaml"):
        named |= set(re.findall(r"results/[\w./-]+\.(?:pt|json)", path.read_text()))
    named |= {e.spec for e in ENTRIES if e.spec.startswith("results/")}
    named.add("results/leaderboard.json")  # where `sagu evaluate` places a score
    assert len(named) > 5
    carried = shipped()
    for rel in sorted(named):
        assert (REPO / rel).is_file(), rel
        assert rel in carried, f"{rel} is named but not in setup.py's SHIPPED"
    assert {"conf/config.yaml", "conf/hydra/help/train.yaml"} <= carried
    assert (REPO / "results/training/readme_quick/s0/eval.json").is_file()
    assert "results/training/readme_quick/s0/eval.json" not in carried  # run records stay in the repository
