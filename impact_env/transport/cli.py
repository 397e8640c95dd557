"""``impact-env scenarios``, ``show`` and ``run`` for impact scenarios (called by :mod:`impact_env.cli`).

``run`` drives :class:`~impact_env.transport.gym_env.TransportEnv` with a controller (``zero``, ``random``, the
expert, a saved model) for one or more seeds and reports robustness, impacts and fuel; the expert draws its
own figure of an episode (executed against planned).
"""

from __future__ import annotations

import argparse
import textwrap

from impact_env.cli_options import save_summary, save_video, transport_options
from impact_env.errors import ImpactEnvError


def list_scenarios() -> None:
    """The table of shipped scenarios."""
    from impact_env.transport.scenario import load_scenario, scenario_names

    print(f"{'name':<22}{'robots':>7}{'objects':>8}{'e':>6}{'tf_s':>7}  description")
    for name in scenario_names():
        sc = load_scenario(name)
        print(f"{name:<22}{len(sc.robots):>7}{len(sc.objects):>8}{sc.restitution:>6.2f}{sc.tf_s:>7.0f}  "
              f"{sc.description}")


def show_scenario(args: argparse.Namespace) -> int:
    from impact_env.transport.plotting import save_scenario_figure
    from impact_env.transport.scenario import load_scenario

    sc = load_scenario(args.scenario)
    path = save_scenario_figure(sc, args.out)
    print(f"wrote {path}")
    print(textwrap.fill(f"task: {' '.join(sc.task.split())}", width=100, subsequent_indent="      "))
    return 0


def run_scenario(args: argparse.Namespace) -> int:
    """``run`` for an impact scenario."""
    from impact_env.controllers import make_controller
    from impact_env.rollout import run_episodes, statistics
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.plotting import count_impacts
    from impact_env.transport.scenario import load_scenario

    if (args.fidelity, args.energy_penalty, args.pull_speed_mps, args.max_active) != ("kinematic", 0.0, None, None):
        raise ImpactEnvError("--fidelity, --energy-penalty, --pull-speed-mps and --max-active apply to tether "
                             "stations, not to impact scenarios")
    sc = load_scenario(args.scenario)
    options = transport_options(args)
    env = TransportEnv(sc, render_mode="rgb_array" if args.video else None, **options)
    controller = make_controller(args.controller, sc, plan=args.plan, trust_pickle=True if args.trust_pickle else None,
                                 allow_other_scenario=True if args.allow_other_scenario else None)
    results = []
    for res in run_episodes(env, controller, args.seed, args.episodes, record_first=bool(args.video)):
        results.append(res)
        hits, contacts = count_impacts(sc, res.impacts)
        print(f"episode {len(results)}/{args.episodes} seed={res.seed}: robustness={res.robustness:+.4f} m "
              f"success={res.success} impacts={hits} (robot-object; {contacts} contacts in all) "
              f"fuel={res.fuel_Ns:.2f} N s ({res.steps} steps, {res.wall_time_s:.2f} s)", flush=True)
    first = results[0]
    save_video(args.video, first, env)
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
