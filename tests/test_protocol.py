"""The protocols' registry (billiards/protocol.py): one description per protocol, asked by every
package instead of comparing a protocol's name as a string, and one player per protocol that
plays a unit for any agent (the benchmark's ``PROTOCOLS``)."""

import ast
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from billiards.protocol import PROTOCOLS, Protocol, find_protocol, get_protocol

PACKAGE = Path(__file__).resolve().parents[1] / "billiards"
NAMES = {p.value for p in Protocol}


def test_every_protocol_has_one_description_and_reads_as_its_name():
    assert set(PROTOCOLS) == set(Protocol)
    for p in Protocol:
        spec = p.spec
        assert spec.kind is p and PROTOCOLS[p] is spec
        assert get_protocol(p.value) is p and find_protocol(p.value) is p
        assert p == p.value and f"{p}" == p.value  # written to records, configs and JSON as its name
        lo, hi, whole = spec.value_range(7)
        assert lo <= hi and whole is spec.whole
        assert spec.words(1).startswith("1 ") and spec.words(3).startswith("3 ")
    assert {p for p in Protocol if p.spec.by_innings} == {Protocol.INNINGS, Protocol.P1}
    assert [p for p in Protocol if p.spec.two_player] == [Protocol.MATCH]


def test_an_unknown_protocol_is_refused_naming_the_protocols():
    with pytest.raises(ValueError, match="unknown protocol 'p2'; the protocols are innings, p1, p3, match"):
        get_protocol("p2")
    assert find_protocol("p2") is None and find_protocol(3) is None and find_protocol(None) is None


def _literal_names(node) -> bool:
    if isinstance(node, ast.Constant):
        return node.value in NAMES
    return isinstance(node, (ast.Tuple, ast.List, ast.Set)) and any(_literal_names(e) for e in node.elts)


@pytest.mark.slow  # over a second (the fast tier holds the in-process tests under one)
def test_no_module_compares_a_protocols_name_as_a_string():
    """Outside the registry a protocol is its enum member: ``==``/``!=`` against a protocol's
    name, ``x in ("innings", "p1")`` and a dict spelled by protocol names are refused."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name == "protocol.py" and path.parent == PACKAGE:
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            where = f"{path.relative_to(PACKAGE.parent)}:{getattr(node, 'lineno', '?')}"
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                for op, right, left in zip(node.ops, sides[1:], sides):
                    if isinstance(op, (ast.Eq, ast.NotEq)) and (_literal_names(left) or _literal_names(right)):
                        found.append(f"{where}: {ast.unparse(node)}")
                    elif isinstance(op, (ast.In, ast.NotIn)) and not isinstance(right, ast.Constant) and _literal_names(right):
                        found.append(f"{where}: {ast.unparse(node)}")
            elif isinstance(node, ast.Dict):
                keys = {k.value for k in node.keys if isinstance(k, ast.Constant)}
                if len(keys & NAMES) >= 2 and keys & {"p1", "p3"}:
                    found.append(f"{where}: a dict keyed by protocol names")
    assert not found, "\n".join(found)


@pytest.mark.slow
def test_every_protocol_plays_a_unit_for_any_agent_within_its_tracks_rules():
    """The benchmark plays every protocol through its protocol object; each protocol's first
    unit, played by the nearest-red reference agent on a track of that protocol (cut short), gives
    a record the track's rules accept and values inside the protocol's range."""
    from billiards.bench.adapters import NearestRedAgent
    from billiards.bench.protocols import PROTOCOLS, record_problem
    from billiards.bench.run import play_unit, unit_values
    from billiards.bench.tracks import TRACKS
    from billiards.physics import get_params

    assert set(PROTOCOLS) == set(Protocol) and all(p.kind is k for k, p in PROTOCOLS.items())
    for protocol in Protocol:
        track = next(t for t in TRACKS.values() if t.protocol is protocol)
        if protocol.spec.two_player:  # one short match against the random player
            track = dataclasses.replace(track, units=1, target=2, max_innings=6, opponents=("random",),
                                        ratings=(("random", 1000.0),), anchor="random")
        else:
            track = dataclasses.replace(track, units=3, block=3, shots=min(track.shots, 4))
        agent = NearestRedAgent(get_params(track.physics))
        rec = {"unit": 0, **play_unit(agent, track, 0)}
        assert record_problem(track, rec) is None, (protocol, rec)
        values = unit_values(track, [rec])
        lo, hi, _ = protocol.spec.value_range(track.shots)
        assert values and all(lo <= v <= hi for v in values), (protocol, values)
        assert track.values_problem(values) is None
        assert np.isfinite(rec["cpu_s"])
