"""Where the tests find the repository and their data, wherever in ``tests/`` a test file sits."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The repository's root (the folder holding ``impact_env/``, ``planners/``, ``tests/``)."""
DATA = ROOT / "tests" / "data"
"""The tests' data files (``tests/data/``): plans, models, scenarios and cells written before a change."""
