"""A commit's ``impact_env/`` and ``planners/`` in a temporary folder, for benchmarks that time the current
code against an older one in the same run (``benchmarks.expert --timing``, ``benchmarks.expert_profile --ref``,
``benchmarks.replanner_qp --ref``), and where such a tree keeps what the benchmarks instrument.

:func:`run_in_tree` calls a benchmark function in a fresh Python whose ``impact_env`` and ``planners`` are the
tree's: the child starts in the tree (``python -m``, so the tree is first on its path) with the repository
root on ``PYTHONPATH`` after it (for ``benchmarks``); nothing edits ``sys.path``. The function's module must
import nothing of the packages at import time (the tree may predate what this checkout imports), and neither
does this module, so that ``python -m benchmarks.git_tree`` runs under any tree.
"""

from __future__ import annotations

import importlib
import os
import pickle
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def export_tree(ref: str, prefix: str = "impact_env_ref_",
                paths: tuple[str, ...] | None = ("impact_env", "planners")) -> str:
    """``git archive`` of the ref's ``paths`` (by default impact_env/ and planners/; None: the whole tree),
    unpacked into a new temporary folder."""
    out = tempfile.mkdtemp(prefix=prefix)
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref, *(paths or ())], check=True,
                             capture_output=True).stdout
    with tempfile.TemporaryFile() as f:
        f.write(archive)
        f.seek(0)
        with tarfile.open(fileobj=f) as tar:
            tar.extractall(out, filter="data")
    return out


def run_in_tree(tree: str | os.PathLike, function: str, *args: Any) -> Any:
    """``function(*args)`` (``"benchmarks.module:name"``; arguments and result pickled) in a new process that
    imports ``impact_env`` and ``planners`` from ``tree``; its output goes to this process's. A failure in the
    child raises RuntimeError with the child's exit status (its traceback is on stderr above)."""
    with tempfile.TemporaryDirectory(prefix="impact_env_tree_job_") as job:
        inputs, result = Path(job) / "args.pkl", Path(job) / "result.pkl"
        inputs.write_bytes(pickle.dumps((function, args)))
        path = os.pathsep.join([str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])
        done = subprocess.run([sys.executable, "-m", "benchmarks.git_tree", str(inputs), str(result)],
                              cwd=tree, env={**os.environ, "PYTHONPATH": path}, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"{function} under {tree} exited with status {done.returncode}")
        return pickle.loads(result.read_bytes())


def package_origins() -> dict[str, str]:
    """The folders ``impact_env`` and ``planners`` are imported from, in this process."""
    import impact_env
    import planners

    return {module.__name__: str(Path(module.__file__).parent) for module in (impact_env, planners)}


def segment_qp_module() -> ModuleType:
    """The module holding the replanner's QP class (``_SegmentQP``, ``_qp``) in the tree first on the path:
    ``planners.online.segment_qp``, or ``planners.online.replanner`` in trees from before that split."""
    try:
        import planners.online.segment_qp as module
    except ImportError:
        import planners.online.replanner as module
    return module


def _child(inputs: str, result: str) -> None:
    function, args = pickle.loads(Path(inputs).read_bytes())
    module_name, _, name = function.partition(":")
    value = getattr(importlib.import_module(module_name), name)(*args)
    Path(result).write_bytes(pickle.dumps(value))


if __name__ == "__main__":
    _child(*sys.argv[1:])
