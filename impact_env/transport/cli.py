"""``impact-env scenarios``, ``show`` and ``run`` for impact scenarios (called by :mod:`impact_env.cli`).

``run`` drives :class:`~impact_env.transport.gym_env.TransportEnv` with a controller (``zero``, ``random``, the
expert, a saved model) for one or more seeds and reports robustness, impacts and fuel; the expert draws its
own figure of an episode (executed against planned).
"""

from __future__ import annotations

import argparse
import textwrap

from impact_env.cli_options import (
    check_world_options,
    print_catalogue,
    run_and_report,
    save_summary,
    transport_options,
)

# impact-env scenarios: (title, format, value) of each column between the name and the description
COLUMNS = (("robots", ">7", lambda sc: len(sc.robots)), ("objects", ">8", lambda sc: len(sc.objects)),
           ("e", ">6.2f", lambda sc: sc.restitution), ("tf_s", ">7.0f", lambda sc: sc.tf_s))


def list_scenarios() -> None:
    """The table of shipped scenarios."""
    from impact_env.transport.scenario import load_scenario, scenario_names

    print_catalogue("name", scenario_names(), load_scenario, COLUMNS)


def show_scenario(args: argparse.Namespace) -> int:
    from impact_env.transport.plotting import save_scenario_figure
    from impact_env.transport.scenario import load_scenario

    sc = load_scenario(args.scenario)
    path = save_scenario_figure(sc, args.plot)
    print(f"wrote {path}")
    print(textwrap.fill(f"task: {' '.join(sc.task.split())}", width=100, subsequent_indent="      "))
    return 0


def run_scenario(args: argparse.Namespace) -> int:
    """``run`` for an impact scenario."""
    from impact_env.controllers import make_controller
    from impact_env.rollout import EpisodeResult, statistics
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.plotting import count_impacts
    from impact_env.transport.scenario import load_scenario

    check_world_options(args, impact=True, station=False, what="impact scenarios")
    sc = load_scenario(args.scenario)
    options = transport_options(args)
    env = TransportEnv(sc, render_mode="rgb_array" if args.video else None, **options)
    controller = make_controller(args.controller, sc, plan=args.plan, trust_pickle=True if args.trust_pickle else None,
                                 allow_other_scenario=True if args.allow_other_scenario else None)

    def details(res: EpisodeResult) -> str:
        hits, contacts = count_impacts(sc, res.impacts)
        return f"impacts={hits} (robot-object; {contacts} contacts in all) fuel={res.fuel_Ns:.2f} N s"

    results = run_and_report(args, env, controller, details)
    first = results[0]
    if args.plot:
        if hasattr(controller, "plot_episode"):  # the expert draws executed against planned (Fig. 6)
            controller.plot_episode(first, args.plot)
        else:
            from impact_env.transport.plotting import plot_run

            plot_run(sc, first.times_s, first.positions, first.impacts, first.robustness, args.plot)
        print(f"wrote {args.plot}")
    summary = {
        "scenario": sc.name, "controller": args.controller, "env_options": options,
        # the first episode's numbers at the top level; every episode under "episodes"
        **{k: v for k, v in first.summary().items()
           if k in ("success", "robustness", "impacts", "fuel_Ns", "controller_ms", "controller_report")},
        **statistics(results),
        "episodes": [r.summary() for r in results],
    }
    save_summary(args.json, summary)
    env.close()
    return 0
