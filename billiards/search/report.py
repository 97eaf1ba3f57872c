"""Table 6 from search runs: ``results.json`` files written by ``search.py``.

Rows are proposers; columns are P1 h=2 and PUCT (mean points per 100-shot inning) and P3 h=2
and PUCT (mean chain length, longest in brackets), with the paper's figures beside ours.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from tabulate import tabulate

from billiards.protocol import Protocol
from billiards.tables import paper_tables

COLUMNS = [(Protocol.P1, "h2"), (Protocol.P1, "puct"), (Protocol.P3, "h2"), (Protocol.P3, "puct")]


def physics_of(res: dict) -> str:
    """The table a search result played (every result since the physics presets names it)."""
    return res.get("physics") or "unknown"


def find_results(dirs) -> list[dict]:
    """Every search result (a JSON object with protocol, search and proposer) under ``dirs``;
    unreadable JSON files are warned about on stderr and skipped."""
    found = []
    for d in dirs:
        d = Path(d)
        files = [d] if d.is_file() else sorted(d.rglob("*.json"))
        for f in files:
            try:
                data = json.loads(f.read_text())
            except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
                print(f"warning: skipping {f}: not readable JSON ({err})", file=sys.stderr)
                continue
            if isinstance(data, dict) and {"protocol", "search", "proposer"} <= data.keys():
                data["_path"] = str(f)
                found.append(data)
    return found


def _cell(res: dict | None, protocol: str) -> str:
    """A cell, marked wherever the run departs from the caption's protocol: fewer P1 innings or
    other inning lengths, capped P3 chains, fewer P3 seeds, and an interrupted (partial) run."""
    if res is None:
        return "—"
    extra = res.get("extra", {})
    notes = []
    if Protocol(protocol) is Protocol.P1:
        innings, shots = extra.get("n_innings"), extra.get("shots_per_inning")
        if innings and innings != 100:
            notes.append(f"{innings} inn.")
        if shots and shots != 100:
            notes.append(f"{shots}-shot innings")
        text = f"{res['mean']:.2f}"
    else:
        capped, seeds = extra.get("cap"), len(extra.get("seeds", [])) or None
        if capped and capped != 10000:
            notes.append(f"cap {capped}")
        if seeds and seeds != 10:
            notes.append(f"{seeds} chains")
        text = f"{res['mean']:.1f} ({res['max']:.0f}" + "".join(f", {n}" for n in notes) + ")"
        notes = []
    if extra.get("partial"):
        notes.append("partial")
    return text + (f" ({', '.join(notes)})" if notes else "")


def paper_table6() -> dict[str, dict]:
    """The paper's Table 6 figures by proposer (conf/experiment/table6.yaml)."""
    return {name: row.figures for name, row in paper_tables()["table6"].rows.items()}


def _paper(name: str, protocol: str, kind: str) -> str:
    v = paper_table6().get(name, {}).get(f"{protocol}_{kind}")
    if v is None:
        return "—"
    return f"{v:.2f}" if Protocol(protocol) is Protocol.P1 else f"{v[0]:g} ({v[1]})"


def table6_markdown(results: list[dict]) -> str:
    """The Table 6 layout, one table per physics (and per execution noise: runs under noise are
    never mixed with exact ones); the last run found wins where a cell has several."""
    by_physics: dict[str, list[dict]] = {}
    for r in results:
        noise = r.get("noise") or "none"
        by_physics.setdefault(physics_of(r) + ("" if noise == "none" else f"`, execution noise `{noise}"), []).append(r)
    return "\n".join(_table6(physics, rs) for physics, rs in sorted(by_physics.items()))


def _table6(physics: str, results: list[dict]) -> str:
    cells: dict[tuple[str, str, str], dict] = {}
    for r in results:
        cells[(r["proposer"], r["protocol"], r["search"])] = r
    paper = list(paper_table6())
    names = sorted({k[0] for k in cells}, key=lambda n: (n not in paper, paper.index(n) if n in paper else 0, n))
    rows = [[name] + [f"{_cell(cells.get((name, p, k)), p)} \\| {_paper(name, p, k)}" for p, k in COLUMNS] for name in names]
    caption = ("Table 6: proposers at 400 simulations per shot. P1: points per 100-shot random-start inning (100 innings); "
               "P3: canonical-start chain length before the first miss or foul, mean (longest). Ours | paper. "
               "(n inn.), (n-shot innings), (n chains): a run that departs from that protocol; cap: chains stopped "
               f"at that length; partial: an interrupted run. Physics: `{physics}`.")
    table = tabulate(rows, headers=["proposer", "P1 h=2", "P1 PUCT", "P3 h=2 mean (max)", "P3 PUCT mean (max)"],
                     tablefmt="github", disable_numparse=True)
    return f"{caption}\n\n{table}\n"
