"""Signal Temporal Logic over body position traces (the paper's Eq. 2a-2d).

* :func:`parse` turns text such as ``F[0,100] in(O1, goal) & G[0,100] !in(R1, W1)`` into a syntax tree of
  :class:`Formula` nodes (bounds in seconds), which the planner also compiles into MILP constraints;
* :func:`robustness` / :func:`robustness_signal` evaluate it offline on a trace (vectorised numpy);
* :class:`OnlineMonitor` gives the same numbers one environment step at a time, for dense rewards;
  :func:`impact_env.stl.compiled.compiled_monitor` the same again, from C, for the formula classes the shipped
  tasks use (what the impact environments run);
* :func:`progress` rewrites a formula for the rest of a trace once a prefix of it is known.
"""

from __future__ import annotations

from impact_env.stl.formula import (
    Always,
    And,
    Constant,
    Eventually,
    FalseFormula,
    Formula,
    InRegion,
    Not,
    Or,
    TrueFormula,
    Until,
    conjuncts,
    horizon_steps,
    interval_steps,
)
from impact_env.stl.monitor import OnlineMonitor
from impact_env.stl.parser import parse
from impact_env.stl.progression import progress, without_constants
from impact_env.stl.robustness import robustness, robustness_signal

__all__ = [
    "Always", "And", "Constant", "Eventually", "FalseFormula", "Formula", "InRegion", "Not", "OnlineMonitor", "Or",
    "TrueFormula", "Until", "conjuncts", "horizon_steps", "interval_steps", "parse", "progress", "robustness",
    "robustness_signal", "without_constants",
]
