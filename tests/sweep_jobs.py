"""Module-level job functions for the sweep tests (workers import them by name)."""

from __future__ import annotations

import os
import time
from pathlib import Path

from impact_env.errors import ScenarioError


def square_after(job: tuple[int, float]) -> int:
    """``k * k`` after sleeping ``delay`` s: jobs finish out of order when the delays decrease."""
    k, delay = job
    time.sleep(delay)
    return k * k


def fail_on(job: int) -> int:
    if job == 2:
        raise ScenarioError("job 2 is a bad scenario")
    if job == 3:
        raise ZeroDivisionError("job 3 divided by zero")
    return job


def threads(_: object) -> dict:
    import torch

    return {"omp": os.environ.get("OMP_NUM_THREADS"), "torch": torch.get_num_threads()}


def read_shared(job: tuple) -> dict:
    """The bytes of a shared file or folder, read through :func:`impact_env.sweep.local_path`, and where."""
    from impact_env.sweep import local_path

    handle, name = job
    path = Path(local_path(handle))
    target = path / name if path.is_dir() else path
    return {"path": str(path), "bytes": target.read_bytes()}


def worker_pid(_: object) -> int:
    """The process that ran the job."""
    return os.getpid()
