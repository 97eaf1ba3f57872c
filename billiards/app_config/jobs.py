"""Every job of a multirun, composed before any runs: :func:`job_configs` (what Hydra's basic
sweeper would launch), :func:`validate_jobs` (each job validated, each problem said once with
the jobs that have it) and :func:`fixed_job_config` (for a sweeper that composes its own jobs)."""

from __future__ import annotations

from omegaconf import DictConfig

def fixed_job_config(config: DictConfig) -> tuple[DictConfig, set[str]]:
    """For a sweeper that composes its own jobs (Optuna ...): the job config with every
    override that is not a sweep applied, and the keys the sweeper will set (its
    ``hydra.sweeper.params`` and the command line's sweep overrides)."""
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    loader = GlobalHydra.instance().config_loader()
    parser = OverridesParser.create(config_loader=loader)
    swept = {str(k) for k in (config.hydra.sweeper.get("params") or {})}
    fixed = []
    for override in parser.parse_overrides(list(config.hydra.overrides.task)):
        if override.is_sweep_override():
            swept.add(override.key_or_group)
        else:
            fixed.append(override.input_line)
    return loader.load_sweep_config(config, fixed), swept


def job_configs(config: DictConfig) -> list[DictConfig]:
    """Every job config a multirun of ``config`` would launch (what Hydra's basic sweeper
    composes, including ``hydra.sweeper.params`` of experiment presets)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.global_hydra import GlobalHydra
    from hydra.core.override_parser.overrides_parser import OverridesParser

    loader = GlobalHydra.instance().config_loader()
    arguments = [f"{k}={v}" for k, v in (config.hydra.sweeper.get("params") or {}).items()]
    arguments += list(config.hydra.overrides.task)
    overrides = OverridesParser.create(config_loader=loader).parse_overrides(arguments)
    batches = BasicSweeper.split_arguments(overrides, None)
    return [loader.load_sweep_config(config, list(job)) for batch in batches for job in batch]


def validate_jobs(config: DictConfig, validate, errors: tuple[type[BaseException], ...] = (Exception,)) -> None:
    """Compose every job of a basic-sweeper multirun and ``validate`` each, before any job
    runs: SystemExit with each problem once, naming the jobs that have it (``every job of the
    multirun (9)`` when all do; ``errors`` are the exceptions that mean an invalid config), or
    naming the job that does not compose (Hydra would only warn and go on)."""
    try:
        jobs = job_configs(config)
    except Exception as err:
        raise SystemExit(f"Error: {err}") from None
    failing: dict[str, list[list[str]]] = {}  # message -> the jobs it is the problem of, in order
    for job in jobs:
        try:
            validate(job)
        except errors as err:
            failing.setdefault(str(err), []).append(list(job.hydra.overrides.task))
    if failing:
        said = []
        for message, which in failing.items():
            if len(which) == 1:
                said.append(f"job {which[0]}: {message}")
            elif len(which) == len(jobs):
                said.append(f"every job of the multirun ({len(jobs)}): {message}")
            else:
                said.append(f"{len(which)} of {len(jobs)} jobs ({', '.join(map(str, which))}): {message}")
        raise SystemExit("Error: " + "\n".join(said))


BASIC_SWEEPER = "hydra._internal.core_plugins.basic_sweeper.BasicSweeper"
