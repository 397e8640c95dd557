"""The batched world needs torch (the ``[rl]`` extra): without it these tests are not collected.

The tests run one torch thread each: pytest-xdist already runs one worker per core, and more threads than
cores make every parallel region wait for a descheduled thread.
"""

import importlib.util

if importlib.util.find_spec("torch") is None:
    collect_ignore_glob = ["test_*.py", "backends.py"]
else:
    import torch

    torch.set_num_threads(1)
