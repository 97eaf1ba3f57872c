"""The paper's tables, defined once as data: ``conf/experiment/<table>.yaml``.

Each experiment preset is a Hydra multirun over its rows and seeds (what ``python train.py
experiment=table4`` or ``python search.py experiment=table6`` runs), and carries, under
``paper``, the table's title, its columns and per row the paper's figures. A training row is a
``variant`` (``conf/variant/<table>/<row>.yaml`` sets its overrides and records ``table`` and
``row`` in every run's config); a row ``same_as`` another table's row is that row's runs,
trained once (its figures are the source's, updated by its own). The reproduction campaign
(:mod:`billiards.campaign`), the reports and ``results/reproduction.json`` all read this module;
nothing else names a paper figure.

Loading reads YAML (``yaml.safe_load``) and parses the sweep with Hydra's own override parser:
no code runs and nothing is composed.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from billiards.files import ROOT

EXPERIMENTS = ROOT / "conf" / "experiment"
VARIANTS = ROOT / "conf" / "variant"
# the figures a training row may give (std beside mean), and a search row's cells
TRAIN_FIGURES = ("mean", "std", "max", "foul_inn", "foul_sh", "succ_sh", "canonical", "rand_eval")
SEARCH_CELLS = ("p1_h2", "p1_puct", "p3_h2", "p3_puct")
ROW_KEYS = ("label", "same_as", "compared_with", "from")


class TableError(ValueError):
    """A table definition that does not hold together; the message names the file and the key."""


@dataclass(frozen=True)
class Row:
    table: str
    name: str
    label: str
    figures: dict = field(default_factory=dict)  # the paper's; a same_as / compared_with row's start from its source's
    same_as: str | None = None  # "<table>/<row>" whose runs this row is
    compared_with: str | None = None  # a row beside a table: the row it is shown against
    trained_from: str | None = None  # a search row's proposer: the training row it was exported from

    @property
    def key(self) -> str:
        return f"{self.table}/{self.name}"


@dataclass(frozen=True)
class Table:
    name: str
    app: str  # train | search
    title: str
    columns: tuple[str, ...]
    rows: dict[str, Row]
    sweep: dict[str, tuple[str, ...]]  # hydra.sweeper.params, each parsed into its values
    steps: int | None = None  # the paper's training budget per run (paper_steps)

    @property
    def seeds(self) -> list[int]:
        return [int(s) for s in self.sweep.get("seed", ("0",))]

    def search_cells(self) -> list[tuple[str, str, str]]:
        """A search table's cells, (proposer, method, protocol) in sweep order; a protocol preset
        named ``<protocol>_<variant>`` (``p3_paper``) is its protocol (its results say ``p3``)."""
        return [(proposer, method, option.partition("_")[0]) for proposer in self.sweep["proposer"]
                for method in self.sweep["search"] for option in self.sweep["protocol"]]

    def trained(self) -> list[str]:
        """The rows this table's own runs train (``variant=<table>/<row>`` in its sweep)."""
        return [v.split("/", 1)[1] for v in self.sweep.get("variant", ())]


def _sweep(params: dict, where: str) -> dict[str, tuple[str, ...]]:
    from hydra.core.override_parser.overrides_parser import OverridesParser

    parser, out = OverridesParser.create(), {}
    for key, value in (params or {}).items():
        try:
            override = parser.parse_override(f"{key}={value}")
        except Exception as err:  # Hydra's grammar errors have no common base worth naming
            raise TableError(f"{where}: hydra.sweeper.params.{key}={value!r} does not parse ({err})") from None
        out[key] = tuple(override.sweep_string_iterator()) if override.is_sweep_override() else (str(override.value()),)
    return out


def _read(path: Path) -> dict | None:
    """A preset's YAML if it defines a paper table (``cpu_hour`` and others do not), else None."""
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as err:
        raise TableError(f"{path}: not readable YAML ({err})") from None
    if not isinstance(data, dict) or "paper" not in data:
        return None
    if not isinstance(data["paper"], dict):
        raise TableError(f"{path}: 'paper' must be a mapping (title, columns, rows)")
    return data


def _parse(name: str, data: dict, where: str) -> Table:
    paper = data["paper"]
    app = paper.get("app", "train")
    if app not in ("train", "search"):
        raise TableError(f"{where}: paper.app must be train or search, got {app!r}")
    allowed = ROW_KEYS + (TRAIN_FIGURES if app == "train" else SEARCH_CELLS)
    rows = {}
    for row, spec in (paper.get("rows") or {}).items():
        if not isinstance(spec, dict) or (unknown := sorted(set(spec) - set(allowed))):
            raise TableError(f"{where}: paper.rows.{row} must be a mapping of {', '.join(allowed)}"
                             + (f" (unknown: {', '.join(unknown)})" if isinstance(spec, dict) else ""))
        rows[row] = Row(name, str(row), str(spec.get("label", row)), {k: v for k, v in spec.items() if k not in ROW_KEYS},
                        spec.get("same_as"), spec.get("compared_with"), spec.get("from"))
    columns = tuple(paper.get("columns") or ())
    if bad := [c for c in columns if c not in TRAIN_FIGURES]:
        raise TableError(f"{where}: paper.columns {bad} are not figures ({', '.join(TRAIN_FIGURES)})")
    sweep = _sweep(data.get("hydra", {}).get("sweeper", {}).get("params"), where)
    table = Table(name, app, str(paper.get("title", name)), columns, rows, sweep,
                  int(data["paper_steps"]) if app == "train" and "paper_steps" in data else None)
    if app == "train":
        for variant in sweep.get("variant", ()):
            group, _, row = variant.partition("/")
            if group != name or row not in rows or rows[row].same_as:
                raise TableError(f"{where}: the sweep's variant={variant} is not one of this table's own rows")
            if not (VARIANTS / f"{variant}.yaml").is_file():
                raise TableError(f"{where}: variant={variant} has no conf/variant/{variant}.yaml")
        if missing := [r for r, spec in rows.items() if not spec.same_as and not spec.compared_with and r not in table.trained()]:
            raise TableError(f"{where}: rows {missing} are neither trained by the sweep nor same_as another table's row")
    return table


@functools.cache
def paper_tables() -> dict[str, Table]:
    """Every paper table preset under ``conf/experiment/`` by name, rows' ``same_as`` resolved
    (the source's figures, updated by the row's own); :class:`TableError` if one is wrong."""
    raw = {p.stem: _parse(p.stem, data, str(p.relative_to(ROOT)))
           for p in sorted(EXPERIMENTS.glob("*.yaml")) if (data := _read(p)) is not None}
    def source(name: str, row_name: str, ref: str) -> Row:
        t, _, r = ref.partition("/")
        if t not in raw or r not in raw[t].trained():
            raise TableError(f"conf/experiment/{name}.yaml: rows.{row_name} names {ref}, which is not a trained row")
        return raw[t].rows[r]

    out = {}
    for name, table in raw.items():
        rows = {}
        for row_name, row in table.rows.items():
            if row.trained_from is not None:
                source(name, row_name, row.trained_from)
            if ref := row.same_as or row.compared_with:
                figures = {**source(name, row_name, ref).figures, **row.figures}
                row = Row(name, row_name, row.label, figures, row.same_as, row.compared_with, row.trained_from)
            rows[row_name] = row
        out[name] = Table(table.name, table.app, table.title, table.columns, rows, table.sweep, table.steps)
    return out


def row(key: str) -> Row:
    """The row ``"<table>/<row>"``; KeyError naming the tables if there is none."""
    table, _, name = key.partition("/")
    try:
        return paper_tables()[table].rows[name]
    except KeyError:
        raise KeyError(f"no paper table row {key!r} (tables: {', '.join(paper_tables())})") from None


__all__ = ["Row", "Table", "TableError", "paper_tables", "row"]
