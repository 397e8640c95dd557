"""Planners for anchor-pull (tether) transport, in the layers of the thesis and beyond it.

- the thesis's pipeline (Sec. 4): :mod:`~planners.tether.decomposition` (MP3, Sec. 4.1),
  :mod:`~planners.tether.extension` (Sec. 4.2), :mod:`~planners.tether.automaton` (region graph and hybrid
  automaton, Sec. 4.3), :mod:`~planners.tether.smt` (divide and conquer with z3, Sec. 4.4) and
  :mod:`~planners.tether.drh` (the automaton in dReach's input language);
- the exact planner: :mod:`~planners.tether.reachability` (backward reachability over the anchors'
  visibility polygons, fewest pulls, proof of infeasibility), on the geometry of :mod:`~planners.tether.geometry`;
- :mod:`~planners.tether.plan` (the TetherPlan both planners write, its JSON form and its check) and
  :mod:`~planners.tether.expert` (the controller that flies a plan in the tether environments).
"""
