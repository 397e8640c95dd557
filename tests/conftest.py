"""Settings for every test, and the plans of the shipped scenarios as session fixtures.

The plans are the committed files of ``tests/data/plans/shipped/`` (:mod:`tests.shipped_plans` says why and
how they are made and kept honest): no test solves a shipped scenario's plan that another test needs too.
Only the packages' light modules are imported here; a fixture imports what it needs when it is used.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    from impact_env.transport.scenario import Scenario
    from planners.plan import Plan
    from tests.shipped_plans import ShippedPlans

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")
os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def shipped_plans() -> ShippedPlans:
    """The committed plans: ``shipped_plans.sr("corridor")``, ``shipped_plans.ir("relay")``; each file is read
    once per worker and shared, its arrays read-only (``copy.deepcopy`` one to change it)."""
    from tests.shipped_plans import ShippedPlans

    return ShippedPlans()


@pytest.fixture(scope="session")
def ir_lab(shipped_plans) -> tuple[Scenario, Plan]:
    """throw_and_catch_exp (the lab experiment) and its committed impact-robust plan (delta = 0.05 m/s)."""
    from impact_env.transport.scenario import load_scenario

    return load_scenario("throw_and_catch_exp"), shipped_plans.ir("throw_and_catch_exp")
