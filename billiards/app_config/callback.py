"""The Hydra callback every app's config names (``hydra.callbacks.validate``): the app's
``validate`` before Hydra writes anything, for every job of a multirun, then the claim of the
run's directories (:mod:`billiards.app_config.rundirs`)."""

from __future__ import annotations

from hydra.experimental.callback import Callback

from .jobs import BASIC_SWEEPER
from .rundirs import claim_run_directory, claim_sweep_directories

class ValidatingCallback(Callback):
    """A Hydra callback (``hydra.callbacks.validate`` in an app's config) that validates before
    Hydra creates the run directory -- for a basic-sweeper multirun, every job's config first --
    so a bad command line fails at once, writes nothing, and exits with the message (Hydra would
    only warn); then claims the run's directories (:func:`claim_run_directory`,
    :func:`claim_sweep_directories`: "Whose directory" in docs/reliability.md). Subclasses set
    ``validate`` (a function raising ValueError)."""

    validate = None

    def _validate(self, config) -> None:
        try:
            type(self).validate(config)
        except (ValueError, OSError) as err:
            raise SystemExit(f"Error: {err}") from None

    def on_run_start(self, config, **kwargs) -> None:
        self._validate(config)
        claim_run_directory(config)

    def on_multirun_start(self, config, **kwargs) -> None:
        if config.hydra.sweeper._target_ != BASIC_SWEEPER:
            self._validate(config)
            claim_sweep_directories(config)
            return
        claim_sweep_directories(config, type(self).validate, errors=(ValueError, OSError))
