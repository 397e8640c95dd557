"""Online control (paper Sec. VI-VII): what runs every control step while a plan is flown.

- :mod:`planners.online.impact_model`: the closed-form inverse of the disc impact law;
- :mod:`planners.online.replanner`: the two-body replanner of a robot's pre- and post-impact segments, with
  velocity and acceleration bounds and safe-segment limits (world box, obstacles, other robots);
- :mod:`planners.online.mpc` (with ``freeflyer`` and ``mpc_specs``): the impact-aware MPC;
- :mod:`planners.online.sampling`: vectorised sampling of a plan's curves;
- :mod:`planners.online.reference`: reference selection (the replanner around impacts, the plan elsewhere) and
  the :class:`~planners.online.reference.ContactStrategy` hook;
- :mod:`planners.online.keep_off`: the MPC's keep-off constraints and the replanner's limits;
- :mod:`planners.online.bookkeeping`: planned impacts observed, unplanned contacts per pair;
- :mod:`planners.online.identification`: restitution and mass ratio from observed impacts;
- :mod:`planners.online.mission`: mission-level replanning with the offline planner.

The expert (:mod:`planners.expert`) composes them.
"""
