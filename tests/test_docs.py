"""The README and docs/ say what is true: every relative link resolves (to a file, and to a
heading where it names one), every repository file they name exists, every ``python train.py``
/ ``search.py`` / ``match.py`` / ``evaluate.py`` line composes and validates as the app would
(in process, through Hydra's compose API), and every other ``python`` line -- a module of the
package or a script of benchmarks/ -- answers ``--help`` and takes the options it is given."""

from __future__ import annotations

import importlib
import re
import shlex
import sys
from pathlib import Path

import pytest
from conftest import APP_CONFIGS

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
APPS = APP_CONFIGS  # entry point -> (its config, the modules that register its schema and checks)
PLACEHOLDER = re.compile(r"<[^>]*>|\.\.\.|\bRUN_DIR\b|\bDIR\b|\bFILE\b|\$\{?[A-Z]")


def _rel(page: Path) -> str:
    return page.relative_to(REPO).as_posix()


def _prose(text: str) -> str:
    """The page without its fenced code blocks (links and file names are read from the prose)."""
    return re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)


# ----------------------------------------------------------------------------- links


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip()).lower()
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(page: Path) -> set[str]:
    return {_slug(m.group(1)) for m in re.finditer(r"^#+\s+(.*)$", _prose(page.read_text()), flags=re.M)}


def _links():
    for page in PAGES:
        for m in re.finditer(r"!?\[[^\]]*\]\(([^)\s]+)\)", _prose(page.read_text())):
            target = m.group(1)
            if not re.match(r"^[a-z]+:", target):
                yield pytest.param(page, target, id=f"{_rel(page)}->{target}")


@pytest.mark.parametrize("page,target", list(_links()))
def test_every_relative_link_resolves(page, target):
    path, _, anchor = target.partition("#")
    dest = (page.parent / path).resolve() if path else page
    assert dest.exists(), f"{_rel(page)} links to {target}, which does not exist"
    assert dest.is_relative_to(REPO), f"{_rel(page)} links outside the repository: {target}"
    if anchor and dest.suffix == ".md":
        assert anchor in _anchors(dest), f"{_rel(page)} links to #{anchor}, which is no heading of {_rel(dest)}"


# ----------------------------------------------------------------------------- named files

TOP = ("billiards/", "tests/", "docs/", "conf/", "benchmarks/", "results/", ".ci/")


def _named_files():
    for page in PAGES:
        names = set()
        for span in re.findall(r"`([^`\n]+)`", _prose(page.read_text())):
            for token in re.findall(r"[\w./-]+", span.split("::")[0]):
                if token.startswith(TOP) and not PLACEHOLDER.search(span.split("::")[0]):
                    names.add(token.rstrip(".,;:"))
        for name in sorted(names):
            yield pytest.param(page, name, id=f"{_rel(page)}:{name}")


def _exists(name: str) -> bool:
    if any(ch in name for ch in "*{[") or re.search(r"seed[0-9]*(-[0-9]+)?$|_$", name):
        return True  # a pattern, or a prefix of a family of files
    return (REPO / name).exists() or any(REPO.glob(name.rstrip("/") + ".*"))


@pytest.mark.parametrize("page,name", list(_named_files()))
def test_every_repository_file_a_page_names_exists(page, name):
    assert _exists(name), f"{_rel(page)} names {name}, which is not in the repository"


def _named_tests():
    for page in PAGES:
        for path, name in sorted(set(re.findall(r"(tests/[\w/]+\.py)::(\w+)", page.read_text()))):
            yield pytest.param(page, path, name, id=f"{_rel(page)}:{path}::{name}")


@pytest.mark.parametrize("page,path,name", list(_named_tests()))
def test_every_test_a_page_cites_exists(page, path, name):
    text = (REPO / path).read_text() if (REPO / path).is_file() else ""
    assert re.search(rf"^def {name}\(", text, flags=re.M), f"{_rel(page)} cites {path}::{name}, which is not a test there"


# ----------------------------------------------------------------------------- commands


def _commands():
    """(page, argv) for every ``python ...`` command of a page: a line of a code block (with its
    continuations) or an inline code span; prompts, comments and shell pipelines cut off."""
    for page in PAGES:
        text = page.read_text()
        found = []
        for block in re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.S | re.M):
            found += re.findall(r"^\s*(?:\$ )?(python [^\n]*(?:\\\n[^\n]*)*)", block, flags=re.M)
        found += re.findall(r"^ {4}(python [^\n]*)", text, flags=re.M)
        found += [s for s in re.findall(r"`(python [^`]*)`", _prose(text))]
        for line in found:
            line = re.sub(r"\\\n", " ", line)
            line = re.split(r"\s+#|\s&&\s|\s\|\s|;", line)[0]
            line = " ".join(line.split())
            if PLACEHOLDER.search(line) or not line.strip():
                continue
            try:
                argv = shlex.split(line)[1:]
            except ValueError:
                continue  # an inline span that shows only the start of a command
            yield page, argv, "refus" in _line_of(text, line)


def _line_of(text: str, command: str) -> str:
    """The line (or table row) a command appears on: a command shown as refused says so there."""
    head = command.split()[1] if len(command.split()) > 1 else command
    for row in text.splitlines():
        if head in row and all(word in row for word in command.split()[1:3]):
            return row
    return ""


def _app_commands():
    seen = set()
    for page, argv, refused in _commands():
        if argv and argv[0] in APPS and tuple(argv) not in seen:
            seen.add(tuple(argv))
            yield pytest.param(argv, refused, id=f"{_rel(page)}:{' '.join(argv)}")


def _readers_own(args: list[str]) -> bool:
    """A command that names the reader's own files (a run of theirs to resume, an agent or a
    model file they wrote, a GPU) is composed but not validated: its files are not here."""
    import torch

    for arg in args:
        key, _, value = arg.partition("=")
        if key == "resume" or value.startswith(("outputs/", "sb3:")) or (value == "cuda" and not torch.cuda.is_available()):
            return True
        if re.search(r"\.(pt|py|zip)(:\w+)?$", value) and not (REPO / value.split(":")[0]).exists():
            return True
    return False


@pytest.mark.slow
@pytest.mark.parametrize("argv,refused", list(_app_commands()))
def test_every_app_command_composes_and_validates(argv, refused, monkeypatch):
    """What ``python <app> ... --cfg job`` would print composes, and the app's own validator (the
    one its Hydra callback runs before anything is written) accepts it -- or refuses it, where
    the page shows the command as one that is refused. ``--help`` and ``--cfg`` lines compose."""
    from hydra import compose, initialize_config_dir
    from hydra.utils import get_class

    from billiards.app_config import override_errors

    app, args = argv[0], [a for a in argv[1:] if a not in ("-m", "--multirun")]
    flags = [a for a in args if a.startswith("--")]
    if flags:
        assert set(args) <= {"--help", "--cfg", "job", "hydra", "--resolve"}, argv
        args = []
    if any(a.startswith("hydra/sweeper=optuna") for a in args):
        pytest.importorskip("hydra_plugins.hydra_optuna_sweeper")
    assert not override_errors(args), override_errors(args)
    for module in APPS[app][1]:  # register the app's schema and checks, as its entry point does
        importlib.import_module(module)
    monkeypatch.chdir(REPO)
    with initialize_config_dir(config_dir=str(REPO / "conf"), version_base="1.3"):
        cfg = compose(APPS[app][0], overrides=args, return_hydra_config=True)
    if flags or _readers_own(args) or (app == "evaluate.py" and not args):  # a bare `python evaluate.py` names the app
        return
    validator = get_class(cfg.hydra.callbacks.validate._target_)
    validate = getattr(validator, "validate", None) or sys.modules[validator.__module__].validate
    if refused:
        with pytest.raises((ValueError, SystemExit)):
            validate(cfg)
    else:
        validate(cfg)


def _other_commands():
    seen = {}
    for page, argv, _ in _commands():
        if not argv or argv[0] in APPS or argv[0] in ("-c", "-X"):
            continue
        if argv[0] == "-m":
            if len(argv) < 2 or not argv[1].startswith("billiards"):
                continue  # pip, pytest: not the project's
            target, rest = ("-m", argv[1]), argv[2:]
        elif argv[0].endswith(".py"):
            target, rest = (argv[0],), argv[1:]
        else:
            continue
        sub = (rest[0],) if rest and re.fullmatch(r"[a-z][a-z-]*", rest[0]) else ()
        options = {a.split("=")[0] for a in rest if a.startswith("--")}
        key = target + sub
        seen.setdefault(key, (page, set()))[1].update(options)
    for key, (page, options) in sorted(seen.items()):
        yield pytest.param(key, sorted(options), id=f"{_rel(page)}:{' '.join(key)}")


def _help(command: tuple[str, ...], monkeypatch, capsys) -> str:
    """What ``python <command> --help`` prints, run in this process (runpy, as ``python -m`` or
    ``python script.py`` runs it): argparse prints the help and exits 0 before any work."""
    import runpy

    monkeypatch.chdir(REPO)
    if command[0] == "-m":
        module, rest = command[1], list(command[2:])
        monkeypatch.setattr(sys, "argv", [module, *rest, "--help"])
        run = lambda: runpy.run_module(module, run_name="__main__", alter_sys=True)
    else:
        script, rest = str(REPO / command[0]), list(command[1:])
        monkeypatch.setattr(sys, "argv", [script, *rest, "--help"])
        monkeypatch.syspath_prepend(str(Path(script).parent))
        run = lambda: runpy.run_path(script, run_name="__main__")
    with pytest.raises(SystemExit) as exit_:
        run()
    out = capsys.readouterr()
    assert exit_.value.code in (0, None), f"python {' '.join(command)} --help: {out.err[-2000:]}"
    return out.out


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:.*found in sys.modules after import of package:RuntimeWarning")
@pytest.mark.parametrize("command,options", list(_other_commands()))
def test_every_module_and_script_command_answers_help_and_takes_its_options(command, options, monkeypatch, capsys):
    text = _help(command, monkeypatch, capsys)
    missing = [o for o in options if o not in text]
    assert not missing, f"python {' '.join(command)} takes no {missing} (its --help: {text[-1500:]})"
