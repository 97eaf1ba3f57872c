"""The one config dialect of the Hydra apps (``train.py``, ``search.py``, ``match.py``,
``evaluate.py``: schemas in :mod:`billiards.rl.config`, :mod:`billiards.search.config`,
:mod:`billiards.league.config`, :mod:`billiards.bench.config`), one job a module:
:mod:`~billiards.app_config.schema` (the shared root schema :class:`AppConfig`, how an app
registers its schemas, the resolvers the YAML uses, the ``--help`` text),
:mod:`~billiards.app_config.jobs` (every job of a multirun composed and validated before any
runs), :mod:`~billiards.app_config.rundirs` (whose directory: a run's, a sweep's and each job's
directory claimed before Hydra writes anything; :func:`path_problem`),
:mod:`~billiards.app_config.callback` (:class:`ValidatingCallback`, the Hydra callback that
validates and then claims), :mod:`~billiards.app_config.bounds` (numbers in range, the allowed
resolvers and the resolved copy an app's check sees), :mod:`~billiards.app_config.overrides`
(configs are data on the command line: :func:`override_errors`) and
:mod:`~billiards.app_config.guard` (configs are data once composed: :func:`composition_errors`,
installed in Hydra's loader by :func:`guard_command_line`; docs/reliability.md). Imports Hydra
and OmegaConf, not torch and not the simulator's kernels: loading it is fast. Every name is
imported from here (``from billiards.app_config import ...``).
"""

from .bounds import (ALLOWED_RESOLVERS, INT_BOUND, RESOLVER_CALL, numeric_bound_errors, resolved_config, resolver_errors,
                     upper_bound_errors)
from .callback import ValidatingCallback
from .guard import composition_errors, guard_command_line, install_composition_guard
from .jobs import BASIC_SWEEPER, fixed_job_config, job_configs, validate_jobs
from .overrides import (ALLOWED_FLAGS, CODE_KEYS, CODE_NODES, FILE_NAME, FLAGS_WITH_VALUE, FORBIDDEN_KEYS, LOCKED_NODES,
                        LOGGING_CODE_KEYS, LOGGING_NODES, LOGGING_REFERENCES, NODE_RESOLVERS, OPTION_NAME, SWEEP_PARAMS,
                        override_errors)
from .rundirs import (HYDRA_RECORDS, READ_LIMIT, RUN_KINDS, SWEEP_RECORDS, RunDirectoryError, RunFinished, RunKind,
                      claim_run_directory, claim_sweep_directories, path_problem, run_directory_problem, sweep_directory_problem)
from .schema import RESOLVERS, RESUME_AUTO, ROOTS, SCHEMA_GROUP, AppConfig, register_app, register_resolvers

__all__ = ["AppConfig", "BASIC_SWEEPER", "RESUME_AUTO", "SCHEMA_GROUP", "ValidatingCallback", "composition_errors", "fixed_job_config",
           "guard_command_line", "install_composition_guard", "job_configs", "numeric_bound_errors", "override_errors",
           "register_app", "register_resolvers", "validate_jobs",
           # whose directory
           "RUN_KINDS", "RunDirectoryError", "RunFinished", "RunKind", "claim_run_directory", "claim_sweep_directories",
           "path_problem", "run_directory_problem", "sweep_directory_problem", "READ_LIMIT", "HYDRA_RECORDS", "SWEEP_RECORDS",
           # the schema's registry and resolvers
           "ROOTS", "RESOLVERS",
           # numbers in range, the resolved config
           "INT_BOUND", "upper_bound_errors", "ALLOWED_RESOLVERS", "RESOLVER_CALL", "resolver_errors", "resolved_config",
           # configs are data
           "ALLOWED_FLAGS", "FLAGS_WITH_VALUE", "CODE_KEYS", "FORBIDDEN_KEYS", "LOGGING_NODES", "LOGGING_CODE_KEYS",
           "LOGGING_REFERENCES", "NODE_RESOLVERS", "CODE_NODES", "LOCKED_NODES", "SWEEP_PARAMS", "OPTION_NAME", "FILE_NAME"]
