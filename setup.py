"""Build hooks (the project's metadata is in pyproject.toml): the files the benchmark needs at run
time that live outside the ``billiards`` folder in the repository (the Hydra configs in ``conf/``,
the shipped models under ``results/``, the leaderboard's snapshot) are carried by the wheel in
``billiards/_data/``, laid out as in the repository, and by the sdist at their repository paths.
``billiards.files.ROOT`` reads them from there when the package is not a source checkout."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

HERE = Path(__file__).resolve().parent
DATA = "billiards/_data"
# What an installed package reads by name: every app's configs, the models that agent names,
# proposers and league players load, and the leaderboard that `sagu evaluate` places a score on.
SHIPPED = ("conf/**/*.yaml", "results/policies/*/*.pt", "results/rankers/*/ranker.pt", "results/values/*.pt",
           "results/rm/model.pt", "results/leaderboard.json")


def shipped(root: Path) -> list[Path]:
    files = sorted({p.relative_to(root) for pattern in SHIPPED for p in root.glob(pattern) if p.is_file()})
    if not any(p.parts[0] == "conf" for p in files):
        raise SystemExit(f"setup.py: no conf/ under {root}: build from the repository or its sdist")
    return files


def copy(files: list[Path], src: Path, dst: Path) -> None:
    for rel in files:
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(src / rel, dst / rel)


class BuildWithData(build_py):
    def run(self):
        super().run()
        if not self.editable_mode:  # an editable install reads the checkout itself
            copy(shipped(HERE), HERE, Path(self.build_lib) / DATA)


class SdistWithData(sdist):
    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        copy(shipped(HERE), HERE, Path(base_dir))


setup(cmdclass={"build_py": BuildWithData, "sdist": SdistWithData})
