"""A commit's ``impact_env/`` and ``planners/`` in a temporary folder, for benchmarks that time the current
code against an older one in the same run (``benchmarks/expert.py --timing``, ``expert_profile.py --ref``,
``replanner_qp.py --ref``). Imports nothing of the package, so a worker can still put the old tree first on
its path."""

from __future__ import annotations

import subprocess
import tarfile
import tempfile
from pathlib import Path


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
