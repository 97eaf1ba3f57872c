"""The agent-spec grammar, parsed once (billiards/bench/spec.py)."""

import pytest

from billiards.bench.spec import AgentError, AgentSpec, SpecKind, spec_name


@pytest.mark.parametrize("text, kind, parts", [
    ("random", SpecKind.BASELINE, {}),
    (" nearest ", SpecKind.BASELINE, {}),
    ("search:h2", SpecKind.SEARCH, {"search": ("h2", "")}),
    ("search:puct/near_miss", SpecKind.SEARCH, {"search": ("puct", "near_miss")}),
    ("league:greedy", SpecKind.LEAGUE, {"player": "greedy"}),
    ("sb3:sac:models/m.zip", SpecKind.SB3, {"sb3": ("sac", "models/m.zip")}),
    ("sb3:sac", SpecKind.SB3, {"sb3": ("sac", "")}),
    ("results/policies/base/seed0.pt", SpecKind.POLICY, {}),
    ("agents/mine.py:act", SpecKind.CODE, {"target": ("agents/mine.py", "act")}),
    ("pkg.mod:act", SpecKind.CODE, {"target": ("pkg.mod", "act")}),
])
def test_each_kind_of_spec_parses_into_its_parts(text, kind, parts):
    spec = AgentSpec.parse(text)
    assert spec.kind is kind and spec.text == text.strip()
    for attr, value in parts.items():
        assert getattr(spec, attr) == value
    assert spec.kind.imports_code == (kind in (SpecKind.SB3, SpecKind.CODE))


def test_a_training_run_directory_is_a_policy_and_a_name_is_never_a_path(tmp_path):
    run = tmp_path / "runs" / "base"
    run.mkdir(parents=True)
    assert AgentSpec.parse(str(run)).kind is SpecKind.POLICY and AgentSpec.parse(str(run)).name == "base"
    assert AgentSpec.parse("results/policies/base/seed0.pt").name == "seed0"
    assert AgentSpec.parse("agents/mine.py:act").name == "mine:act"
    assert AgentSpec.parse("pkg.mod:act").name == "pkg.mod:act"
    assert AgentSpec.parse("search:h2/base").name == "search:h2/base"
    assert spec_name("no/such/folder") == "folder" and spec_name("mine") == "mine"


@pytest.mark.parametrize("text", ["", "greedy", "no/such/folder", "script.py"])
def test_a_spec_that_names_nothing_is_refused_with_the_grammar(text):
    with pytest.raises(AgentError, match="names nothing: give random | nearest | random_aim"):
        AgentSpec.parse(text)
