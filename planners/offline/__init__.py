"""Offline planning (paper Sec. IV-V): mixed-integer programs over Bezier curves, solved before an episode.

- :mod:`planners.offline.spatially_robust`: the spatially robust planner (maximise the STL robustness rho);
- :mod:`planners.offline.impact_robust`: the impact-robust planner (maximise the tolerated post-impact
  velocity error delta);
- :mod:`planners.offline.milp`: the encodings the planners share (time grid and trajectories, impacts, STL,
  collisions) on a small solver-neutral model;
- :mod:`planners.offline.solvers`: the HiGHS, SCIP and Gurobi backends behind one ``solve`` call.
"""
