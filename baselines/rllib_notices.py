"""Ray's and RLlib's notices that ask nothing of the user, kept out of the terminal of an RLlib run.

A short ``impact-env train ppo SCENARIO --engine rllib`` printed, from the driver and again from every env runner:
that PPO runs on RLlib's new API stack ("the new default behavior", which this package chose on purpose), that
``RLModuleConfig`` is deprecated (RLlib builds one inside its own ``RLModule.__init__``; no code of ours passes
it), that gputil is not installed (there is no GPU here), and that token authentication is on (Ray's secure
default for a new local instance, kept). :func:`quiet_notices` drops exactly these
records, matched by logger and text, from the process it runs in: the driver before the algorithm is built,
each env runner when it builds its env (:func:`baselines.rllib_env.make_env`). Every other warning, and every
error, still shows.
"""

from __future__ import annotations

import logging

NOTICES: dict[str, tuple[str, ...]] = {
    "ray.rllib.algorithms.algorithm_config": ("on the new API stack! This is the new default behavior",),
    "ray._common.deprecation": ("RLModule(config=[RLModuleConfig object])",),
    "ray.tune.utils.util": ("Install gputil for GPU system monitoring",),
    # Ray's secure default for a new local instance, announced on every start (setting RAY_AUTH_MODE=token
    # instead would need to happen before ray is imported: Ray caches its config at import)
    "ray._private.authentication.authentication_token_setup": ("Token authentication is enabled for this Ray",),
}


class NoticeFilter(logging.Filter):
    """Drops the records of one logger whose message contains one of ``texts``."""

    def __init__(self, texts: tuple[str, ...]) -> None:
        super().__init__()
        self.texts = texts

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        return not any(text in message for text in self.texts)


def quiet_notices() -> None:
    """Install the filters of :data:`NOTICES` in this process (once; later calls do nothing)."""
    for name, texts in NOTICES.items():
        logger = logging.getLogger(name)
        if not any(isinstance(f, NoticeFilter) for f in logger.filters):
            logger.addFilter(NoticeFilter(texts))
