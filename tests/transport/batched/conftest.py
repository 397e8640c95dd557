"""The batched world needs torch (the ``[rl]`` extra): without it these tests are not collected."""

import importlib.util

if importlib.util.find_spec("torch") is None:
    collect_ignore_glob = ["test_*.py", "backends.py"]
