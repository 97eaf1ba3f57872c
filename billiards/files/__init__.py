"""Files the package writes and reads back, one job a module: :mod:`~billiards.files.paths`
(where the project's files are -- :data:`ROOT`, :data:`CONF_DIR`, :data:`OUTPUTS` -- the names
of a run directory's files, and paths as configs give them and records write them),
:mod:`~billiards.files.atomic` (the one atomic writer for every result file),
:mod:`~billiards.files.runfiles` (the one reader of a run folder's files: regular files only, no
link followed, bounded size and JSON depth), :mod:`~billiards.files.lock` (one writer per run
folder: its lock file), :mod:`~billiards.files.seals` (the sha256 seals sealed files and
records carry), :mod:`~billiards.files.describe` (how a message shows a value read from a file
without quoting it), :mod:`~billiards.files.ledgers` (append-only sealed ledgers, their kinds
and the registry of kinds), :mod:`~billiards.files.summaries` (a run's summary checked against
its ledger: ``python -m billiards.files verify RUN_DIR``, :mod:`~billiards.files.__main__`) and
:mod:`~billiards.files.tensors` (the small sealed ``torch.save`` files with a format tag, and
the checks of what such a file holds). The lowest layer of the package: the standard library
and :mod:`billiards.protocol` only (torch lazily), so anything may import it; every name is
imported from here (``from billiards.files import ...``), and a test that replaces one patches
the module that reads it.
"""

from .atomic import TMP_SUFFIX, atomic_open, atomic_write_bytes, atomic_write_text
from .describe import described, shown_name, shown_number
from .ledgers import (CHAINS, LEDGER_PROVIDERS, MATCHES, RUN_KEY, LedgerError, LedgerKind, LedgerScan, append_record, ledger_kinds,
                      read_ledger, register_ledger, run_identity, scan_ledger)
from .lock import LOCK_FILE, LockHolder, RunLock, RunLockedError, lock_holder, run_folder_names, run_lock
from .paths import (CHAINS_FILE, CHECKPOINT_FILE, CONF_DIR, CONFIG_FILE, EVAL_FILE, EVAL_HISTORY_FILE, IDENTITY_FILE, IN_CHECKOUT,
                    LEAGUE_FILE, MATCHES_FILE, METRICS_FILE, OUTPUTS, PACKAGE, RESULTS_FILE, ROOT, SCORECARD_JSON, SCORECARD_MD,
                    SUMMARY_FILE, UNITS_FILE, display_path, recorded_command, repo_path)
from .runfiles import (MAX_JSON_DEPTH, RUN_FILE_LIMITS, RunFileError, json_depth_problem, open_run_file, parse_json, read_run_bytes,
                       read_run_json, read_run_text, run_file_kind)
from .seals import SEAL_KEY, non_finite_entry, payload_digest, record_digest, sealed_record
from .summaries import main, read_summary, stale_summary, summary_problems, verify
from .tensors import MAX_NESTING, key_problem, load_tagged, plain_data_problem, save_tagged, shape_problem, tensor_problem

__all__ = [
    # paths
    "PACKAGE", "IN_CHECKOUT", "ROOT", "CONF_DIR", "OUTPUTS", "CONFIG_FILE", "CHECKPOINT_FILE", "EVAL_FILE", "EVAL_HISTORY_FILE",
    "METRICS_FILE", "SUMMARY_FILE", "RESULTS_FILE", "CHAINS_FILE", "MATCHES_FILE", "LEAGUE_FILE", "IDENTITY_FILE", "UNITS_FILE",
    "SCORECARD_JSON", "SCORECARD_MD", "repo_path", "display_path", "recorded_command",
    # atomic
    "TMP_SUFFIX", "atomic_open", "atomic_write_bytes", "atomic_write_text",
    # runfiles
    "RUN_FILE_LIMITS", "MAX_JSON_DEPTH", "RunFileError", "run_file_kind", "open_run_file", "read_run_bytes", "read_run_text",
    "json_depth_problem", "parse_json", "read_run_json",
    # lock
    "LOCK_FILE", "RunLockedError", "LockHolder", "RunLock", "run_lock", "lock_holder", "run_folder_names",
    # seals
    "SEAL_KEY", "payload_digest", "non_finite_entry", "record_digest", "sealed_record",
    # describe
    "described", "shown_number", "shown_name",
    # ledgers
    "RUN_KEY", "LedgerError", "run_identity", "LedgerKind", "CHAINS", "MATCHES", "LEDGER_PROVIDERS", "register_ledger", "ledger_kinds",
    "LedgerScan", "scan_ledger", "read_ledger", "append_record",
    # summaries
    "read_summary", "summary_problems", "stale_summary", "verify", "main",
    # tensors
    "MAX_NESTING", "tensor_problem", "key_problem", "plain_data_problem", "shape_problem", "save_tagged", "load_tagged",
]
