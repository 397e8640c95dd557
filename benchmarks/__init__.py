"""The benchmarks: scripts that print a table, run from the repository root as modules
(``python -m benchmarks.robustness``). Those that keep cells write them to ``results/<benchmark>/`` (one
``cells.jsonl`` and its ``table.md``, :mod:`impact_env.results_store`); ``results/README.md`` says which.

Nothing here imports the packages at import time (:mod:`benchmarks.git_tree` runs benchmark functions under
an older commit's packages).
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from impact_env.sweep import Engine, EngineConfig


def open_engine(config: EngineConfig, n_jobs: int | None = None) -> Engine:
    """:func:`impact_env.sweep.open_engine` for a benchmark's sweep. On Ray, this package's job functions
    travel to the workers by value, as a script's own functions do (:func:`send_by_value`)."""
    from impact_env.sweep import open_engine as open_sweep_engine

    if config.name == "ray":
        send_by_value()
    return open_sweep_engine(config, n_jobs)


def send_by_value() -> None:
    """Have Ray pickle this package's functions by value: the nodes of a cluster have the installed (or
    shipped) packages, but not ``benchmarks/``, which is no part of them. A no-op without Ray."""
    try:
        from ray import cloudpickle
    except ImportError:  # open_engine says what to install
        return
    cloudpickle.register_pickle_by_value(sys.modules[__name__])
