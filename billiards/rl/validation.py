"""Validating a training config before anything is written: :func:`validate` (every problem of
the config, :func:`billiards.rl.config.config_errors`, with the files it names read and checked:
a checkpoint to resume, the policy ``algo.init_policy`` starts from) and the Hydra callback
:class:`ValidateConfig` that runs it for train.py (``hydra.callbacks`` in conf/config.yaml).

Apart from :mod:`billiards.rl.config` (the schema) because reading those files takes the
checkpoint and policy modules, which themselves build on the schema; it imports them (and
torch) only when a config names a file, so a refusal stays quick."""

from __future__ import annotations

from typing import Any

from omegaconf import DictConfig

from billiards.app_config import BASIC_SWEEPER, ValidatingCallback, claim_sweep_directories, fixed_job_config

from .config import ConfigError, config_errors


def checkpoint_problem(run_dir) -> str | None:
    """Why the checkpoint of ``run_dir`` cannot be resumed (loaded and checked now; the run reuses
    what was loaded), or None."""
    from .checkpoint import CheckpointError, load_checkpoint  # torch: only when there is a file to read

    try:
        load_checkpoint(run_dir, keep=True)
    except CheckpointError as err:
        return str(err)
    return None


def _init_policy_problem(path, cfg) -> str | None:
    from .policy import init_policy_problem  # torch: only when there is a file to read

    return init_policy_problem(path, cfg)


def errors(cfg: DictConfig) -> list[str]:
    """Every problem of a composed training config, the files it names included."""
    return config_errors(cfg, init_policy_problem=_init_policy_problem, checkpoint_problem=checkpoint_problem)


def validate(cfg: DictConfig) -> None:
    """Raise :class:`ConfigError` listing every problem of a composed training config, the files
    it names (a resumed checkpoint, algo.init_policy) read and checked now."""
    errs = errors(cfg)
    if errs:
        raise ConfigError("invalid training config:\n  - " + "\n  - ".join(errs))


def _refuse_other_apps_preset(config: DictConfig) -> None:
    """``experiment=table6`` names search.py's preset: say so, before anything is composed or written."""
    paper = config.get("paper")
    if isinstance(paper, DictConfig) and paper.get("app", "train") != "train":
        raise SystemExit(f"Error: experiment={config.get('table')} is a {paper.app}.py preset: "
                         f"python {paper.app}.py -m experiment={config.get('table')}")


def _validate_job(cfg: DictConfig) -> None:
    """:func:`validate`, any other exception it meets raised as a :class:`ConfigError` with the
    same message: the callback exits with it (Hydra would only warn and go on)."""
    try:
        validate(cfg)
    except ValueError:
        raise
    except Exception as err:
        raise ConfigError(str(err)) from None


class ValidateConfig(ValidatingCallback):
    """Hydra callback (``hydra.callbacks`` in conf/config.yaml): validates the training config
    before Hydra creates any directory. For a multirun it composes and validates every job
    first, so one bad job aborts the whole sweep before anything is written. Then it claims the
    run's directories (billiards.app_config, "Whose directory" in docs/reliability.md).

    Hydra turns exceptions raised by callbacks into warnings, so a failure exits the process
    (``SystemExit``, status 1) with the message on stderr. It is search.py's and match.py's
    :class:`~billiards.app_config.ValidatingCallback` with train.py's additions: another app's
    preset is refused first, a multirun prints its sweep directory, and under another sweeper
    (Optuna) what the sweeper does not vary is checked before the study starts.
    """

    validate = staticmethod(_validate_job)

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        _refuse_other_apps_preset(config)
        super().on_run_start(config, **kwargs)

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        _refuse_other_apps_preset(config)
        print(f"sweep: {config.hydra.sweep.dir}", flush=True)
        if config.hydra.sweeper._target_ != BASIC_SWEEPER:
            self._check_fixed_part(config)
            claim_sweep_directories(config)
            return
        super().on_multirun_start(config, **kwargs)  # every job validated, then its directory claimed

    @staticmethod
    def _check_fixed_part(config: DictConfig) -> None:
        """Another sweeper (Optuna) chooses its jobs' values as it goes, so each job validates
        in its task (a bad trial fails on its own; see train.py). What the sweeper does not
        vary is checked here, before the study starts: a problem that would fail every trial
        aborts the sweep at once. Problems that name a swept key are left to the trials."""
        try:
            job, swept = fixed_job_config(config)
            errs = errors(job)
        except Exception as err:  # Hydra would only warn and go on
            raise SystemExit(f"Error: {err}") from None
        errs = [e for e in errs if not any(key in e for key in swept)]
        if errs:
            raise SystemExit("Error: invalid training config (every trial of the sweep would fail):\n  - "
                             + "\n  - ".join(errs))


__all__ = ["ValidateConfig", "checkpoint_problem", "errors", "validate"]
