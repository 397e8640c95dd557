"""Online control (paper Sec. VI-VII): what runs every control step while a plan is flown.

- :mod:`planners.online.impact_model`: the circular two-body impact model and its closed-form inverse;
- :mod:`planners.online.replanner`: the two-body replanner of a robot's pre- and post-impact segments;
- :mod:`planners.online.mpc` (with ``freeflyer`` and ``mpc_specs``): the impact-aware MPC.
"""
