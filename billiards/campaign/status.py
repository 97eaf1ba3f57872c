"""``python -m billiards.campaign status``: done / running / left per table, CPU-hours spent
and an estimate of the CPU-hours left, read from the run dirs and the ledger (no lock: it can
run beside a runner).

CPU-hours spent: a training run's own account (``summary.json``'s ``cpu_seconds``; for an
unfinished run the last ``cpu_time`` of its metrics.csv), a search run's ``seconds``. Work a
kill threw away and process start-up are not in those; the ledger's per-process CPU seconds
(all processes the runner reaped) are printed beside them.

Estimate left: per cost group (``Entry.cost``: the algorithm preset of a training run, the
method of a search run) the CPU seconds per step measured on this campaign's own runs (all
their steps and CPU so far), else the prior in :data:`PRIORS`. Search runs are bounded by
their maximum number of decisions (P3 chains usually end far earlier), so their estimate is
an upper bound, printed apart.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from .ledger import Ledger, entry_dir, entry_done, is_stale, pid_alive, progress, search_resumable, search_seconds
from .runner import MAX_FAILURES
from .spec import Campaign, Entry

# CPU seconds per step (training) or per decision (search) before a campaign has measured its
# own. sac, td3, ppo_paper: measured on the paper's table, 16,384 steps each (budget=smoke
# based, final evaluation of 10 innings), results/campaign/priors.md; the periodic
# evaluations of budget=paper (100 innings every 50k steps) come on top. sac_paper, td3_paper: 5.7
# CPU-h per 1M steps (physics_reference.md §10). h2, puct: ms per decision at 400 simulations
# with a trained 3-policy ensemble on the paper's table, one thread, after the search speed-ups
# (results/bench_search_korean_medium.json, `python benchmarks/bench_search.py --decisions 200
# --puct-decisions 30 --out results/bench_search_korean_medium.json` at 58a3f53): h2 3.2 ms,
# PUCT 12.8 ms (the geometric proposer: 2.7 and 9.6 ms).
PRIORS = {"sac": 2.75e-3, "td3": 1.93e-3, "sac_paper": 2.05e-2, "td3_paper": 2.05e-2, "ppo_paper": 2.22e-3,
          "h2": 3.2e-3, "puct": 1.28e-2}


@dataclass
class EntryState:
    entry: Entry
    state: str  # done | shared | running | stale | failed | waiting | resumable | new
    frames: int = 0  # steps (training) or decisions (search) done
    cpu_seconds: float = 0.0  # the run's own account (0 for shared entries)
    process_cpu_seconds: float = 0.0  # all processes the runner reaped (ledger)
    commits: tuple[str, ...] = ()


def entry_states(campaign: Campaign, root: Path, selected: list[Entry] | None = None) -> list[EntryState]:
    root = Path(root).resolve()
    ledger = Ledger(root, campaign.name)
    by_key = campaign.by_key()
    entries = selected if selected is not None else campaign.entries

    def stale(e: Entry) -> bool:
        return is_stale(ledger, e)

    def done(e: Entry) -> bool:
        return entry_done(campaign, root, ledger, e)

    out = []
    for e in entries:
        src = campaign.source(e)
        run_dir = entry_dir(root, campaign, e)
        rec = ledger.get(src.key) or {}
        p = progress(run_dir) if src.kind == "train" else None
        frames, cpu = (p.frames, p.cpu_seconds) if p else (0, 0.0)
        if src.kind == "search" and (s := search_seconds(run_dir)):
            frames, cpu = s
        if e.same_as:
            state = "shared" if done(e) else "left (shared)"
            frames, cpu = 0, 0.0  # counted once, under the source
        elif stale(e):
            state = "stale"
        elif done(e):
            state = "done"
        elif pid_alive(rec.get("pid"), run_dir):
            state = "running"
        elif rec.get("failures", 0) >= MAX_FAILURES:
            state = "failed"
        elif not all(done(by_key[k]) for k in e.needs()):
            state = "waiting"
        else:
            resumable = p.checkpoint if p else src.kind == "search" and search_resumable(run_dir)
            state = "resumable" if resumable else "new"
        proc = sum(s.get("cpu_seconds") or 0.0 for s in rec.get("starts", [])) if not e.same_as else 0.0
        out.append(EntryState(e, state, frames, cpu, proc, tuple(rec.get("commits", ()))))
    return out


def rates(states: list[EntryState]) -> dict[str, tuple[float, str]]:
    """Per cost group: CPU seconds per step and where the figure comes from."""
    steps, cpu, runs = defaultdict(int), defaultdict(float), defaultdict(int)
    for s in states:
        if s.entry.same_as or s.frames <= 0 or s.cpu_seconds <= 0:
            continue
        steps[s.entry.cost] += s.frames
        cpu[s.entry.cost] += s.cpu_seconds
        runs[s.entry.cost] += 1
    groups = {s.entry.cost for s in states if s.entry.cost}
    out = {}
    for g in sorted(groups):
        if steps[g]:
            out[g] = (cpu[g] / steps[g], f"measured: {runs[g]} runs, {steps[g]:,} steps, {cpu[g] / 3600:.2f} CPU-h")
        elif g in PRIORS:
            out[g] = (PRIORS[g], "prior (billiards/campaign/status.py PRIORS)")
        else:
            out[g] = (PRIORS["sac"], "no measurement and no prior: assumed as sac")
    return out


def left_seconds(s: EntryState, rate: dict[str, tuple[float, str]]) -> float:
    if s.entry.same_as or s.state in ("done", "shared") or s.entry.kind == "export":
        return 0.0
    remaining = max(s.entry.steps - (s.frames if s.entry.kind == "train" else 0), 0)
    return remaining * rate.get(s.entry.cost, (PRIORS["sac"], ""))[0]


COUNTED = ("done", "running", "left")


def summarize(states: list[EntryState]) -> dict[str, dict]:
    """Per table: counts of done (shared included) / running / left, and CPU-hours."""
    r = rates(states)
    tables: dict[str, dict] = {}
    for s in states:
        t = tables.setdefault(s.entry.table, {"entries": 0, "done": 0, "shared": 0, "running": 0, "left": 0,
                                              "stale": 0, "failed": 0, "waiting": 0,
                                              "cpu_h": 0.0, "process_cpu_h": 0.0, "train_left_h": 0.0, "search_left_h": 0.0})
        t["entries"] += 1
        if s.state in ("done", "shared"):
            t["done"] += 1
            t["shared"] += s.state == "shared"
        elif s.state == "running":
            t["running"] += 1
        else:
            t["left"] += 1
            if s.state in ("stale", "failed", "waiting"):
                t[s.state] += 1
        t["cpu_h"] += s.cpu_seconds / 3600
        t["process_cpu_h"] += s.process_cpu_seconds / 3600
        t["search_left_h" if s.entry.kind == "search" else "train_left_h"] += left_seconds(s, r) / 3600
    return tables


def status_text(campaign: Campaign, root: Path, selected: list[Entry] | None = None, jobs: int = 2,
                verbose: bool = False) -> str:
    states = entry_states(campaign, root, selected)
    tables = summarize(states)
    lines = [f"campaign {campaign.name} in {Path(root).resolve()}: {runner_state(Path(root))}", "",
             "| table | entries | done (shared) | running | left (waiting, failed, stale) | CPU-h spent | "
             "CPU-h in processes | CPU-h left, training | CPU-h left, search (bound) |",
             "|---|---|---|---|---|---|---|---|---|"]
    total = defaultdict(float)
    for name, t in sorted(tables.items()):
        for k, v in t.items():
            total[k] += v
        lines.append(_row(name, t))
    lines.append(_row("total", total))
    lines.append("")
    lines.append(f"wall-clock left at {jobs} runs at a time, one core each: about "
                 f"{total['train_left_h'] / jobs:.1f} h of training + at most {total['search_left_h'] / jobs:.1f} h of search")
    lines.append("")
    lines.append("CPU seconds per step (training) / per decision (search), by cost group:")
    for g, (rate, where) in rates(states).items():
        lines.append(f"  {g}: {rate * 1000:.2f} ms ({where})")
    commits = sorted({c for s in states for c in s.commits})
    lines.append(f"commits the runs ran under: {', '.join(commits) or 'none yet'}")
    if verbose:
        lines += ["", "| entry | state | steps | CPU min | commits |", "|---|---|---|---|---|"]
        for s in states:
            lines.append(f"| {s.entry.key} | {s.state}{f' = {s.entry.same_as}' if s.entry.same_as else ''} | "
                         f"{s.frames:,} / {s.entry.steps:,} | {s.cpu_seconds / 60:.1f} | {', '.join(s.commits)} |")
    return "\n".join(lines) + "\n"


def runner_state(root: Path) -> str:
    """Whether a runner holds the campaign's lock (it is released when the runner exits)."""
    import fcntl

    path = root / "campaign.lock"
    if not path.is_file():
        return "no runner active"
    with path.open() as f:
        try:
            fcntl.flock(f, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return f"a runner is active (pid {f.read().strip() or '?'})"
        fcntl.flock(f, fcntl.LOCK_UN)
    return "no runner active"


def _row(name: str, t: dict) -> str:
    n = lambda k: int(t[k])  # noqa: E731
    return (f"| {name} | {n('entries')} | {n('done')} ({n('shared')}) | {n('running')} | "
            f"{n('left')} ({n('waiting')}, {n('failed')}, {n('stale')}) | {t['cpu_h']:.2f} | {t['process_cpu_h']:.2f} | "
            f"{t['train_left_h']:.2f} | {t['search_left_h']:.2f} |")
