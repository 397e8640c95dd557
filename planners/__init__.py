"""The planners and the expert controller, by layer: the plan noun (:mod:`planners.plan`), the impact law
(:mod:`planners.impact_law`), the offline planners (:mod:`planners.offline`), the online layer
(:mod:`planners.online`), the expert and its stacks (:mod:`planners.expert`), and the tether planners
(:mod:`planners.tether`).

The modules that moved in 0.3.0 keep their old import paths for one release, answered by
:mod:`impact_env.moved_modules` with a ``DeprecationWarning``.
"""

from impact_env import moved_modules

moved_modules.register({
    "planners.funnels": "planners.plan.funnels",
    "planners.plan_files": "planners.plan.files",
    "planners.plan_schema": "planners.plan.schema",
    "planners.plotting": "planners.plan.plotting",
    "planners.wrappers": "planners.expert.wrappers",
    "planners.offline.sr_planner": "planners.offline.spatially_robust",
    "planners.offline.ir_planner": "planners.offline.impact_robust",
})
