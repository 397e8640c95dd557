"""A commit's ``impact_env/`` and ``planners/`` in a temporary folder, for benchmarks that time the current
code against an older one in the same run (``benchmarks/expert.py --timing``, ``expert_profile.py --ref``,
``replanner_qp.py --ref``), and where such a tree keeps what the benchmarks instrument. Imports nothing of
the package at import time, so a worker can still put the old tree first on its path."""

from __future__ import annotations

import subprocess
import tarfile
import tempfile
from pathlib import Path
from types import ModuleType


def export_tree(ref: str, prefix: str = "impact_env_ref_") -> str:
    """``git archive`` of the ref's impact_env/ and planners/, unpacked into a new temporary folder."""
    out = tempfile.mkdtemp(prefix=prefix)
    root = Path(__file__).resolve().parents[1]
    archive = subprocess.run(["git", "-C", str(root), "archive", ref, "impact_env", "planners"], check=True,
                             capture_output=True).stdout
    with tempfile.TemporaryFile() as f:
        f.write(archive)
        f.seek(0)
        with tarfile.open(fileobj=f) as tar:
            tar.extractall(out, filter="data")
    return out


def segment_qp_module() -> ModuleType:
    """The module holding the replanner's QP class (``_SegmentQP``, ``_qp``) in the tree first on the path:
    ``planners.online.segment_qp``, or ``planners.online.replanner`` in trees from before that split."""
    try:
        import planners.online.segment_qp as module
    except ImportError:
        import planners.online.replanner as module
    return module
