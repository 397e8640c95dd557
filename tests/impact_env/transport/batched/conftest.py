"""The batched world needs torch (the ``[rl]`` extra): without it these tests are not collected.

torch is looked up, not imported, while the suite is collected (importing it takes seconds, which every run
would pay, even one that selects none of these tests): the test modules import torch and the batched package
inside their tests, and name dtypes by string (``"float32"``, resolved with ``getattr(torch, name)``).

The tests run one torch thread each: pytest-xdist already runs one worker per core, and more threads than
cores make every parallel region wait for a descheduled thread.
"""

import importlib.util

import pytest

if importlib.util.find_spec("torch") is None:
    collect_ignore_glob = ["test_*.py", "backends.py"]


@pytest.fixture(autouse=True, scope="session")
def _one_torch_thread():
    import torch

    torch.set_num_threads(1)
