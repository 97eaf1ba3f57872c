"""The agent-spec grammar, parsed once into an :class:`AgentSpec` (docs/benchmark.md).

A spec is what a person writes for ``agent=``:

* ``random``, ``nearest``, ``random_aim``: the reference baselines;
* ``search:<search>[/<proposer>]``: a search of ``search.py`` at the track's budget;
* ``league:<player>``: a player of ``conf/match.yaml``;
* ``sb3:<algo>:<model.zip>``: a saved Stable-Baselines3 model;
* a ``.pt`` file or a training run directory of this project;
* ``path/to/file.py:name`` or ``package.module:name``: the person's own code.

Everything that reads a spec (building the agent, naming it, the leaderboard's own entries, the
viewer deciding what it may build again) asks the parsed spec for its kind and parts; no other
module splits a spec's text.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path


class AgentError(ValueError):
    """A bad agent: a spec that names nothing usable, or an agent that answers wrongly."""


class SpecKind(StrEnum):
    BASELINE = "baseline"
    SEARCH = "search"
    LEAGUE = "league"
    SB3 = "sb3"
    POLICY = "policy"
    CODE = "code"

    @property
    def imports_code(self) -> bool:
        """Building it imports code the spec names (the person's module, or a pickled model)."""
        return self in (SpecKind.SB3, SpecKind.CODE)


BASELINES = ("random", "nearest", "random_aim")
PREFIXED = (SpecKind.SEARCH, SpecKind.LEAGUE, SpecKind.SB3)  # written <kind>:<body>
GRAMMAR = ("random | nearest | random_aim, file.py:name, package.module:name, sb3:<algo>:<model.zip>, a policy .pt file or "
           "training run dir, search:<search>[/<proposer>] or league:<player>")


def _stem(path: str) -> str:
    return Path(re.split(r"[/\\]", path.rstrip("/\\"))[-1]).stem or path


@dataclass(frozen=True)
class AgentSpec:
    """A parsed spec: its ``text``, its ``kind`` and its ``body`` (what follows ``<kind>:`` for a
    search, a league player or an SB3 model; the text itself otherwise)."""

    text: str
    kind: SpecKind
    body: str

    @classmethod
    def parse(cls, text) -> AgentSpec:
        """The spec ``text`` (surrounding blanks dropped); an AgentError naming the grammar when it
        names nothing. A directory counts as a training run when it exists (a policy)."""
        text = str(text).strip()
        if text in BASELINES:
            return cls(text, SpecKind.BASELINE, text)
        for kind in PREFIXED:
            if text.startswith(f"{kind.value}:"):
                return cls(text, kind, text[len(kind.value) + 1:])
        if text.endswith(".pt") or (not text.endswith(".py") and text and Path(text).is_dir()):
            return cls(text, SpecKind.POLICY, text)
        if ":" in text:
            return cls(text, SpecKind.CODE, text)
        raise AgentError(f"agent {text!r} names nothing: give {GRAMMAR}")

    @property
    def search(self) -> tuple[str, str]:
        """(search, proposer or "") of a ``search:`` spec."""
        search, _, proposer = self.body.partition("/")
        return search, proposer

    @property
    def player(self) -> str:
        """The league player a ``league:`` spec names."""
        return self.body

    @property
    def sb3(self) -> tuple[str, str]:
        """(algorithm, model file) of an ``sb3:`` spec ("" where missing)."""
        algo, _, path = self.body.partition(":")
        return algo, path

    @property
    def target(self) -> tuple[str, str]:
        """(file.py or package.module, attribute) of a code spec."""
        target, _, attr = self.text.rpartition(":")
        return target, attr

    @property
    def name(self) -> str:
        """The name its agent goes by when given none: never a path of the machine that played
        it. A file or a folder goes by its stem (``agents/mine.py:act`` -> ``mine:act``,
        ``runs/base/seed0.pt`` -> ``seed0``, a training run directory by its own name); any other
        spec (``package.module:act``, ``random``, ``search:h2``) by itself."""
        if self.kind in PREFIXED or self.kind is SpecKind.BASELINE:
            return self.text
        target, attr = self.target
        if self.kind is SpecKind.CODE and target.endswith(".py") and attr.isidentifier():
            return f"{_stem(target)}:{attr}"
        if self.text.endswith(".pt") or re.search(r"[/\\]", self.text):
            return _stem(self.text)
        return self.text


def spec_name(spec) -> str:
    """:attr:`AgentSpec.name` of ``spec``; a text that names nothing goes by itself (a path-like
    one by its last part's stem)."""
    try:
        return AgentSpec.parse(spec).name
    except AgentError:
        text = str(spec).strip()
        return _stem(text) if re.search(r"[/\\]", text) else text


__all__ = ["AgentError", "AgentSpec", "BASELINES", "GRAMMAR", "SpecKind", "spec_name"]
