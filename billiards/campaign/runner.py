"""``python -m billiards.campaign run``: run a campaign's unfinished entries N at a time.

Each entry runs as its own process (``python train.py ...``, ``python search.py ...``,
``python -m billiards.rl.policy export ...``) with cwd = the repository, one thread
(``threads=1``, NUMBA/OMP_NUM_THREADS=1), no progress bar, stdout and stderr appended to
``<run dir>/<kind>.log``. A training run with a ``checkpoint.pt`` continues with
``resume=<run dir>``; a finished entry is skipped; an entry waits until the entries it needs
are done. Entries start in the campaign's order (Tables 1-5 before Table 6's searches).

Stopping. The trainer does not checkpoint on a signal: killing it loses what it did since its
last checkpoint (at most ``budget.checkpoint_every`` steps, 50k at ``budget=paper``). So the
runner *drains* instead of killing where it can: from ``deadline - grace`` on (``--until`` /
``--hours``, ``--grace-minutes``), on a first Ctrl-C / SIGTERM, or when ``<root>/STOP``
appears (``python -m billiards.campaign stop``), it starts nothing new and stops each
training run right after its next checkpoint (or lets it finish): a grace of one checkpoint
interval (about 1.5 minutes of one core for ``algo=sac`` at ``budget=paper``) loses nothing.
A run whose checkpoints come further apart than the grace (the authors' settings,
``algo=sac_paper``: about 13 minutes) drains on its own earlier, :data:`LEAD_MARGIN` of its
checkpoint interval before the deadline (the interval measured between two checkpoints it
wrote while watched, else estimated from its ``eval_history.jsonl`` and
``budget.checkpoint_every``), so the checkpoint it writes then is its last before the deadline
and nothing it did is lost; it is not started again by this runner. 20 s before the deadline,
on a second Ctrl-C or on ``stop --now`` (``<root>/STOP_NOW``) it stops whatever still runs
(SIGTERM to the run's process group, SIGKILL 10 s later, so nothing runs past the deadline);
that loss is bounded as above. A search run gets SIGINT instead: it writes the chains it
finished as a partial ``results.json`` (not counted as done); a P3 then continues from its
next chain (``search.py resume=<dir>``), losing the chain in progress, a P1 starts over.
Searches are not drained (they have no checkpoint to wait for). An export takes seconds.

Restarts. All state lives on disk under the campaign root (:mod:`.ledger`); a second runner on
the same root is refused (an ``flock`` on ``campaign.lock``, released by the kernel when the
process dies, so a power cut leaves no stale lock). Runs that a killed runner left running
are adopted: they occupy their slot until they exit and are not started twice.

Code changes. Every start records the commit it ran under. Training semantics must not change
in the middle of a run: a resume keeps the run's checkpointed config, and an entry whose
arguments in the campaign definition changed since its first start is *stale*: it is not
resumed (nor, if finished, counted as done for the new definition) until
``--restart-stale`` moves its directory aside and runs it from scratch.
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from billiards.provenance import ROOT, git_commit
from billiards.files import recorded_command

from .ledger import (LOGS, STARTS, STOP, STOP_NOW, Ledger, entry_dir, entry_done, fill, is_done, is_stale, pid_alive,
                     progress, search_resumable, utc_now)
from .spec import Campaign, Entry, SpecError

MAX_FAILURES = 3  # starts that ended in an error before an entry is left alone (--retry-failed resets)
KILL_WAIT = 10.0  # seconds between SIGTERM and SIGKILL
HARD_STOP = 20.0  # seconds before the deadline at which whatever still runs is stopped, so all is gone by then
LEAD_MARGIN = 1.15  # a slow-checkpointing run drains this many checkpoint intervals (+ HARD_STOP) before the deadline


def runtime_args(kind: str) -> list[str]:
    """What every process of a campaign gets: one thread, no progress bar, Hydra's log to
    stdout only (the runner writes it into the run dir's log file)."""
    if kind == "export":
        return []
    return ["threads=1", "progress=false", "hydra/job_logging=stdout"]


def command(entry: Entry, run_dir: Path, root: Path) -> tuple[list[str], str]:
    """The command line that advances ``entry`` now, and its mode: ``fresh``, ``resume`` (a
    training run with a checkpoint) or ``export``."""
    py = sys.executable
    if entry.kind == "export":
        sources = [fill(a, root) for a in entry.args]
        return [py, "-m", "billiards.rl.policy", "export", *sources, "--out", str(run_dir)], "export"
    if entry.kind == "search":
        if search_resumable(run_dir):
            return [py, "search.py", f"resume={run_dir}", *runtime_args("search"), f"hydra.run.dir={run_dir}"], "resume"
        return [py, "search.py", *(fill(a, root) for a in entry.args), *runtime_args("search"),
                f"hydra.run.dir={run_dir}"], "fresh"
    if (run_dir / "checkpoint.pt").is_file():
        return [py, "train.py", f"resume={run_dir}", *runtime_args("train")], "resume"
    return [py, "train.py", *(fill(a, root) for a in entry.args), *runtime_args("train"),
            f"hydra.run.dir={run_dir}"], "fresh"


def child_env() -> dict[str, str]:
    env = dict(os.environ)
    env.update(OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="1", MKL_NUM_THREADS="1", HYDRA_FULL_ERROR="1",
               WANDB_MODE=env.get("WANDB_MODE", "offline"))
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    return env


# ----------------------------------------------------------------------------- deadline


def parse_deadline(hours: float | None, until: str | None, now: float | None = None) -> float | None:
    """Epoch seconds of the deadline: ``hours`` from now, or the next ``until`` (HH:MM, local
    time of this machine, today or else tomorrow); None without either."""
    now = time.time() if now is None else now
    if hours is not None and until is not None:
        raise SpecError("give --hours or --until, not both")
    if hours is not None:
        if not hours > 0:
            raise SpecError(f"--hours must be > 0, got {hours}")
        return now + 3600.0 * hours
    if until is None:
        return None
    try:
        hh, mm = (int(x) for x in until.split(":"))
        if not (0 <= hh < 24 and 0 <= mm < 60):
            raise ValueError
    except ValueError:
        raise SpecError(f"--until must be HH:MM (24 h, this machine's local time), got {until!r}") from None
    t = time.localtime(now)
    target = time.mktime((t.tm_year, t.tm_mon, t.tm_mday, hh, mm, 0, 0, 0, -1))
    return target if target > now else target + 86400.0


# ----------------------------------------------------------------------------- the runner


@dataclass
class Slot:
    """A process running one entry: a child of this runner, or adopted from a previous one."""

    entry: Entry
    run_dir: Path
    pid: int
    proc: subprocess.Popen | None = None  # None: adopted
    ckpt_mtime: int | None = None  # checkpoint.pt's mtime when the drain began (None: none yet)
    drain_seen: bool = False  # the drain reached this run: ckpt_mtime holds its checkpoint's mtime then
    draining: bool = False  # checkpointed since the drain began: being stopped
    term_at: float | None = None
    ckpt_seen: int | None = None  # checkpoint.pt's mtime at the last look (watch)
    ckpt_written: int | None = None  # the mtime of the last checkpoint seen written while watched
    interval: float | None = None  # seconds between the last two checkpoints seen written
    estimate: float | None = None  # the interval estimated from the run's history, before any is measured

    def __post_init__(self) -> None:
        self.ckpt_seen = _mtime(self.run_dir / "checkpoint.pt")
        if self.entry.kind == "train":
            self.estimate = checkpoint_interval_estimate(self.run_dir)

    def watch(self) -> None:
        """Look at checkpoint.pt: two checkpoints seen written give the run's interval."""
        mtime = _mtime(self.run_dir / "checkpoint.pt")
        if mtime is not None and mtime != self.ckpt_seen:
            if self.ckpt_written is not None:
                self.interval = (mtime - self.ckpt_written) / 1e9
            self.ckpt_written = mtime
        self.ckpt_seen = mtime

    def checkpoint_interval(self) -> float | None:
        """Seconds between the run's checkpoints: measured, else estimated, else None."""
        return self.interval if self.interval is not None else self.estimate

    def drain_began(self) -> None:
        """Remember the checkpoint the run has now; :meth:`checkpointed` waits for a newer one."""
        self.ckpt_mtime, self.drain_seen = _mtime(self.run_dir / "checkpoint.pt"), True

    def checkpointed(self) -> bool:
        """Whether the run wrote a checkpoint since :meth:`drain_began`: stopping it now loses
        nothing (the trainer writes checkpoint.pt atomically)."""
        mtime = _mtime(self.run_dir / "checkpoint.pt")
        return self.drain_seen and mtime is not None and mtime != self.ckpt_mtime


def checkpoint_interval_estimate(run_dir: Path) -> float | None:
    """Wall seconds between a training run's checkpoints, from its last two periodic evaluations
    in ``eval_history.jsonl`` (cumulative wall time per step) times ``budget.checkpoint_every``
    of its ``config.yaml``; None when the run has not two evaluations or no periodic checkpoints."""
    import yaml

    try:
        every = int(yaml.safe_load((run_dir / "config.yaml").read_text())["budget"]["checkpoint_every"])
        rows = [json.loads(line) for line in (run_dir / "eval_history.jsonl").read_text().splitlines() if line.strip()]
        by_step = {int(r["step"]): float(r["wall_time"]) for r in rows if not r.get("final")}
    except (OSError, ValueError, TypeError, KeyError, yaml.YAMLError):
        return None
    if every <= 0 or len(by_step) < 2:
        return None
    (a, wa), (b, wb) = sorted(by_step.items())[-2:]
    return (wb - wa) / (b - a) * every if wb > wa else None


def _mtime(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except FileNotFoundError:
        return None


@dataclass
class Runner:
    campaign: Campaign
    root: Path
    jobs: int = 2
    deadline: float | None = None
    grace: float = 300.0  # seconds before the deadline from which the runner drains
    only: list[str] | None = None
    restart_stale: bool = False
    retry_failed: bool = False
    poll: float = 2.0
    out: object = None  # where progress lines go (default: sys.stdout)
    slots: list[Slot] = field(default_factory=list)
    drain_requested: bool = False
    stop_now: bool = False
    wound_down: set = field(default_factory=set)  # keys drained early for their long checkpoint interval

    def __post_init__(self) -> None:
        self.root = Path(self.root).resolve()
        self.selected = self.campaign.select(self.only)
        self.ledger = Ledger(self.root, self.campaign.name)
        self.commit = git_commit()

    def say(self, msg: str) -> None:
        print(f"[{utc_now()}] {msg}", file=self.out or sys.stdout, flush=True)

    # ---------------------------------------------------------- per-entry state

    def dir_of(self, entry: Entry) -> Path:
        return entry_dir(self.root, self.campaign, entry)

    def stale(self, entry: Entry) -> bool:
        return is_stale(self.ledger, entry)

    def done(self, entry: Entry) -> bool:
        return entry_done(self.campaign, self.root, self.ledger, entry)

    def ready(self, entry: Entry) -> bool:
        by_key = self.campaign.by_key()
        return all(self.done(by_key[k]) for k in entry.needs())

    def runnable(self) -> list[Entry]:
        """Unfinished entries that may start now, in campaign order."""
        running = {s.entry.key for s in self.slots}
        out = []
        for e in self.selected:
            if e.same_as or e.key in running or e.key in self.wound_down or self.done(e) or not self.ready(e):
                continue
            rec = self.ledger.get(e.key) or {}
            if self.stale(e) and not self.restart_stale:
                continue
            if rec.get("failures", 0) >= MAX_FAILURES and not self.retry_failed:
                continue
            out.append(e)
        return out

    # ---------------------------------------------------------- starting and ending

    def _archive_stale(self, entry: Entry, run_dir: Path) -> None:
        if run_dir.exists():
            target = run_dir.with_name(f"{run_dir.name}.stale-{time.strftime('%Y%m%d-%H%M%S', time.gmtime())}")
            run_dir.rename(target)
            self.say(f"{entry.key}: its arguments changed since it started; old dir moved to {target}")
        rec = self.ledger.record(entry.key)
        rec.update(args=None, failures=0)
        rec.setdefault("archived", []).append(utc_now())

    def launch(self, entry: Entry) -> None:
        run_dir = self.dir_of(entry)
        if self.stale(entry):
            self._archive_stale(entry, run_dir)
        cmd, mode = command(entry, run_dir, self.root)
        run_dir.mkdir(parents=True, exist_ok=True)
        if mode == "fresh":
            (run_dir / "eval_history.jsonl").unlink(missing_ok=True)  # a killed first attempt's, before any checkpoint
        frames = progress(run_dir).frames if entry.kind == "train" else 0
        self.commit = git_commit()  # the checkout may have moved since the last start
        start = {"commit": self.commit, "started": utc_now(), "mode": mode, "frames": frames}
        log = (run_dir / LOGS[entry.kind]).open("a")
        log.write(f"\n===== campaign {self.campaign.name}: {entry.key}, {mode} at commit {self.commit}, {start['started']}\n"
                  f"===== {' '.join(recorded_command(cmd))}\n")
        log.flush()
        proc = subprocess.Popen(cmd, cwd=ROOT, env=child_env(), stdout=log, stderr=subprocess.STDOUT,
                                stdin=subprocess.DEVNULL, start_new_session=True)
        log.close()
        rec = self.ledger.record(entry.key)
        if rec["args"] is None:
            rec["args"] = list(entry.args)
        rec["starts"].append(start)
        if self.commit not in rec["commits"]:
            rec["commits"].append(self.commit)
        rec["pid"] = proc.pid
        self.ledger.save()
        with (run_dir / STARTS).open("a") as f:
            f.write(json.dumps(start | {"command": recorded_command(cmd)}) + "\n")
        self.slots.append(Slot(entry, run_dir, proc.pid, proc))
        self.say(f"start  {entry.key} ({mode}{f' at {frames:,} steps' if frames else ''}), pid {proc.pid}")

    def _reap(self, slot: Slot) -> tuple[int, float | None] | None:
        """(exit status, CPU seconds) once the slot's process has ended, else None."""
        if slot.proc is None:  # adopted: not our child, no exit status
            return None if pid_alive(slot.pid, slot.run_dir) else (-1, None)
        pid, status, usage = os.wait4(slot.pid, os.WNOHANG)
        if pid == 0:
            return None
        rc = os.waitstatus_to_exitcode(status)
        slot.proc.returncode = rc
        return rc, usage.ru_utime + usage.ru_stime

    def finish(self, slot: Slot, rc: int, cpu: float | None) -> None:
        entry = slot.entry
        done = is_done(entry, slot.run_dir, self.root)
        if done:
            outcome = "finished"
        elif slot.draining or self.stop_now:
            outcome = "stopped"
        elif rc in tuple(128 + s for s in (signal.SIGINT, signal.SIGTERM, signal.SIGUSR1)) and entry.kind == "train":
            outcome = "stopped"  # a signal from outside: the run checkpointed that step and exited (not a failure)
        elif slot.proc is None:
            outcome = "ended (adopted, exit status unknown)"
        else:
            outcome = f"failed (exit {rc})"
        rec = self.ledger.record(entry.key)
        if rec["starts"]:
            rec["starts"][-1].update(ended=utc_now(), outcome=outcome, exit=rc if slot.proc else None,
                                     cpu_seconds=None if cpu is None else round(cpu, 2))
        if outcome.startswith("failed"):
            rec["failures"] = rec.get("failures", 0) + 1
        rec["pid"] = None
        self.ledger.save()
        with (slot.run_dir / STARTS).open("a") as f:
            f.write(json.dumps({"ended": utc_now(), "outcome": outcome, "exit": rc,
                                "cpu_seconds": None if cpu is None else round(cpu, 2)}) + "\n")
        log = slot.run_dir / LOGS[entry.kind]
        self.say(f"{'done' if done else 'end'}   {entry.key}: {outcome}"
                 + ("" if done or outcome == "stopped" else f" -- see {log}"))

    def adopt(self) -> None:
        """Processes a previous runner started that still run (it was killed, they were not)."""
        for e in self.selected:
            rec = self.ledger.get(e.key)
            if rec and rec.get("pid"):
                run_dir = self.dir_of(e)
                if pid_alive(rec["pid"], run_dir):
                    self.slots.append(Slot(e, run_dir, rec["pid"], None))
                    self.say(f"adopt  {e.key}: pid {rec['pid']} of an earlier runner still runs it")
                else:
                    rec["pid"] = None
                    if rec["starts"] and "ended" not in rec["starts"][-1]:
                        rec["starts"][-1].update(ended=utc_now(), outcome="lost (the runner and the run were killed)")
        self.ledger.save()

    # ---------------------------------------------------------- stopping

    def terminate(self, slot: Slot) -> None:
        """SIGINT to a search (it writes its finished chains as a partial result), SIGTERM to
        the rest; :meth:`_escalate` sends SIGKILL KILL_WAIT seconds later."""
        if slot.term_at is not None:
            return
        slot.term_at = time.time()
        try:
            os.killpg(slot.pid, signal.SIGINT if slot.entry.kind == "search" else signal.SIGTERM)
        except ProcessLookupError:
            pass

    def _escalate(self) -> None:
        for slot in self.slots:
            if slot.term_at is not None and time.time() - slot.term_at > KILL_WAIT:
                try:
                    os.killpg(slot.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass

    def draining(self) -> bool:
        if (self.root / STOP).exists():
            self.drain_requested = True
        near = self.deadline is not None and time.time() >= self.deadline - self.grace
        return self.drain_requested or near

    def lead_reached(self, slot: Slot) -> bool:
        """Whether a training run must drain now so that its next checkpoint, its last before
        the deadline, comes in time: within LEAD_MARGIN of its interval of the hard stop."""
        if self.deadline is None or slot.entry.kind != "train":
            return False
        interval = slot.checkpoint_interval()
        return interval is not None and time.time() >= self.deadline - HARD_STOP - LEAD_MARGIN * interval

    def _signal(self, signum, frame) -> None:
        if self.drain_requested:
            self.stop_now = True
            self.say("second signal: stopping every run now")
        else:
            self.drain_requested = True
            self.say("signal: starting nothing new, stopping each training run after its next checkpoint "
                     "(again: stop now)")

    # ---------------------------------------------------------- the loop

    def step(self) -> None:
        """One round: reap ended processes, stop what must stop, start what may start."""
        past = self.deadline is not None and time.time() >= self.deadline - HARD_STOP
        if past and not self.stop_now:
            self.stop_now = True
            self.say("deadline reached: stopping every run now")
        if (self.root / STOP_NOW).exists() and not self.stop_now:
            self.stop_now = True
            self.say("stop --now: stopping every run now")
        drain = self.draining()
        for slot in list(self.slots):
            ended = self._reap(slot)
            if ended is not None:
                self.slots.remove(slot)
                self.finish(slot, *ended)
                continue
            slot.watch()
            if self.stop_now:
                self.terminate(slot)
            elif not slot.draining and slot.entry.kind == "train" and (drain or self.lead_reached(slot)):
                if not slot.drain_seen:
                    slot.drain_began()
                    if not drain:
                        self.say(f"drain  {slot.entry.key}: checkpoints every {slot.checkpoint_interval() / 60:.1f} min, "
                                 "its next is its last before the deadline")
                elif slot.checkpointed():
                    slot.draining = True
                    if not drain:
                        self.wound_down.add(slot.entry.key)
                    self.say(f"drain  {slot.entry.key}: stopping right after its checkpoint")
                    self.terminate(slot)
        self._escalate()
        if drain or self.stop_now:
            return
        for entry in self.runnable():
            if len(self.slots) >= self.jobs:
                break
            self.launch(entry)

    def run(self) -> int:
        """Runs until every selected entry is done, nothing more can start, or the deadline;
        returns the number of selected entries not done."""
        self.root.mkdir(parents=True, exist_ok=True)
        lock = (self.root / "campaign.lock").open("a+")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SpecError(f"another runner is working on {self.root} (campaign.lock is held); "
                            f"`python -m billiards.campaign status` shows it") from None
        lock.seek(0)
        lock.truncate()
        lock.write(f"{os.getpid()}\n")
        lock.flush()
        for name in (STOP, STOP_NOW):  # a new start is a new wish to run
            (self.root / name).unlink(missing_ok=True)
        handlers = {}
        if _main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                handlers[sig] = signal.signal(sig, self._signal)
        try:
            self.adopt()
            if self.deadline is not None:
                self.say(f"deadline {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(self.deadline))}, "
                         f"draining from {self.grace / 60:.0f} min before")
            self.say(f"campaign {self.campaign.name} at commit {self.commit}: {len(self.selected)} entries selected, "
                     f"{sum(self.done(e) for e in self.selected)} done, up to {self.jobs} at a time")
            while True:
                self.step()
                if not self.slots and (self.draining() or self.stop_now or not self.runnable()):
                    break
                time.sleep(self.poll)
        finally:
            for sig, old in handlers.items():
                signal.signal(sig, old)
            for name in (STOP, STOP_NOW):
                (self.root / name).unlink(missing_ok=True)
            fcntl.flock(lock, fcntl.LOCK_UN)
            lock.close()
        left = [e for e in self.selected if not self.done(e)]
        self.say(f"runner stops: {len(self.selected) - len(left)} of {len(self.selected)} entries done"
                 + (f"; left: {len(left)} (run again to continue)" if left else ""))
        return len(left)


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()
