"""Where a trainer writes: the run folder that ``--out`` names, or ``<--runs-dir>/<default name>``.

Every trainer of :mod:`baselines` (PPO/SAC, BC, DAgger, BC+RL, residual) has the same two settings,
``out`` and ``runs_dir``; these helpers check them and resolve the folder, so the rule lives in one place.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from impact_env.config_checks import check_text
from impact_env.errors import ImpactEnvError

__all__ = ["check_run_folder", "run_folder_path"]


def check_run_folder(config: Any, default: str) -> None:
    """Check ``config.out`` (a path or None, which means ``<runs_dir>/<default>``) and ``config.runs_dir``."""
    check_text(config, "out", ImpactEnvError, none=f"<runs_dir>/{default}")
    check_text(config, "runs_dir", ImpactEnvError)


def run_folder_path(out: str | None, runs_dir: str, name: str) -> Path:
    """``out`` when given, else ``runs_dir/name``."""
    return Path(out) if out else Path(runs_dir) / name
