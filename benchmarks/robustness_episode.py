"""Re-fly one episode of a robustness-benchmark cell and tell its story impact by impact.

    python -m benchmarks.robustness_episode SCENARIO STACK AXIS LEVEL SEED [--plot out.png] [--plan PLAN]
    python -m benchmarks.robustness_episode two_objects all e 0.3 0 --allow-side-switches \
        --plot docs/img/two_objects_e03_seed0.png
    python -m benchmarks.robustness_episode two_objects all impact 0.02 4 --significance 3

SCENARIO, STACK (``paper``, ``+id``, ``+mission``, ``all``; ``plus_id`` / ``plus_mission`` as in the cell
file names), AXIS and LEVEL (``nominal 0``, ``combined 0``, ``e 0.3``, ``offset 0.1``, ``thrust 0.2``, ...)
and SEED name one episode of :mod:`benchmarks.robustness` (the same plan file, env options and stack);
the episode is flown in this process, deterministically, so it has the cell's robustness.

The story, in time order:

- every contact the env reports; for a robot-object contact, the planned impact the expert's bookkeeping
  matched it to (or "unplanned"), what the replanner asked for (the object's velocity after, the contact
  normal, the restitution it assumed) against what happened, and the **side**: ``cos`` between the asked
  and the observed contact normal (the object's velocity change), below 0 when the robot hit the object
  from the side opposite to the one the impact needs;
- the identification's estimate of the pair after each impact, against the simulator's restitution (with
  ``--significance K``, identification's significance test on at k = K, and its verdict: the estimate in use,
  or the file's value kept);
- every mission check that tried a re-plan: predicted robustness, threshold, outcome, the pending impacts
  the prediction judged unreachable (:mod:`planners.online.reachability`), the new plan's impacts, and its
  **side switches** (:func:`planners.online.side_switch.side_switches`: two consecutive
  impacts on one object by one robot whose velocity changes are more than 90 degrees apart, so that the
  robot must get round the object in between; the planner's bodies are points, its path goes through it),
  with the time left and the time getting round needs;
- the mission monitor's counts (checks, checks that found an unreachable impact, re-plan attempts);
- the task's parts (conjuncts) with their robustness on the flown trace and when their worst sample is.

``--plot`` draws the planned (offline: dotted; the last re-plan: dashed) and flown (solid) paths with the
contacts and re-plans, and each object's distance to its task region over time with the task's windows.
``--allow-side-switches`` flies the episode as the benchmark's cells were flown, before mission re-plans
with a side switch were refused.
"""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from benchmarks.robustness import RESULTS, add_cell_arguments, env_options, expert_config, plan_path
from planners.online.side_switch import side_switches, unflyable_side_switches


# ------------------------------------------------------------------------------------------- recording
@dataclass
class AskedContact:
    """What the replanner asked for an impact: the first query (when the approach began) and the last."""

    first_t_s: float
    t_s: float
    object_position: np.ndarray
    object_velocity: np.ndarray
    restitution: float
    normal: np.ndarray
    object_velocity_after: np.ndarray


class RecordingStrategy:
    """A :class:`~planners.online.reference.ContactStrategy` that delegates and keeps what was asked, per
    (robot, object, planned impact time)."""

    def __init__(self, inner) -> None:
        self.inner = inner
        self.asked: dict[tuple[str, str, float], AskedContact] = {}

    def contact(self, query):
        out = self.inner.contact(query)
        if out is not None:
            key = (query.robot.name, query.obj.name, round(query.impact.time_s, 6))
            first = self.asked[key].first_t_s if key in self.asked else query.t_s
            self.asked[key] = AskedContact(first, query.t_s, np.array(query.object_position, float),
                                           np.array(query.object_velocity, float), float(query.restitution),
                                           np.array(out.normal, float), np.array(out.object_velocity_after, float))
        return out


def recording_book(book_type):
    """A subclass of the expert's impact book that remembers which planned impact each contact completed."""

    class RecordingBook(book_type):
        def reset(self) -> None:
            super().reset()
            self.matches: list[tuple[dict, object]] = []  # (event, PlannedImpact or None)

        def observe(self, events, robots, objects):
            completed = []
            for ev in events:
                done = super().observe([ev], robots, objects)
                self.matches.append((ev, self.impacts[done[0]] if done else None))
                completed += done
            return completed

    return RecordingBook


@dataclass
class EpisodeRecord:
    """Everything the story needs, collected while the episode is flown."""

    plans: list[tuple[float, object]] = field(default_factory=list)  # (time set, Plan)
    # t, robot, obj, mean, std, and with the significance test on: (in use, z, the object's and the robot's
    # reading of the impact), else None
    estimates: list[tuple[float, str, str, float, float, tuple | None]] = field(default_factory=list)


class Recorder:
    """A controller for :func:`impact_env.rollout.run_episode`: the expert, watched after every step."""

    def __init__(self, expert) -> None:
        self.expert = expert
        self.record = EpisodeRecord()
        self._seen = 0

    def reset(self, env=None, seed=None) -> None:
        self.expert.reset(env, seed)
        self.record = EpisodeRecord(plans=[(0.0, self.expert.plan)])
        self._seen = 0

    def act(self, observation, info=None):
        action = self.expert.act(observation, info)
        ex = self.expert
        if ex.plan is not self.record.plans[-1][1]:  # a mission re-plan at this step (the expert's clock)
            t = round((1.0 - float(np.asarray(observation)[-1])) * ex.horizon_steps) * ex.dt
            self.record.plans.append((t, ex.plan))
        measurements = ex.identifier.measurements if ex.config.identification else []
        for m in measurements[self._seen:]:
            est = ex.identifier.estimate(m.robot, m.object)
            decision = ex.identifier.decisions.get((m.robot, m.object))
            # the significance test's decision has a z score; the bounded estimator's an interval
            evidence = (f"z = {decision.z:.1f}" if hasattr(decision, "z")
                        else f"allowed [{decision.low:.3f}, {decision.high:.3f}]") if decision is not None else ""
            verdict = None if decision is None else (decision.in_use, evidence, m.restitution,
                                                     m.restitution_robot_side)
            self.record.estimates.append((m.time_s, m.robot, m.object, est.mean, est.std, verdict))
        self._seen = len(measurements)
        return action


# ------------------------------------------------------------------------------------------ analysis
def task_parts(scenario, positions: np.ndarray, dt: float) -> list[dict]:
    """Each conjunct of the task: its text, robustness on the trace, and the time of its worst sample."""
    from impact_env.stl import Always, Eventually, InRegion, Not, conjuncts, robustness

    names = [b.name for b in scenario.bodies]
    trace = {n: positions[:, i] for i, n in enumerate(names)}
    regions = scenario.region_map()
    out = []
    for part in conjuncts(scenario.formula):
        row = {"part": str(part), "robustness": float(robustness(part, trace, regions, dt)), "worst_s": None}
        inner = part.child if isinstance(part, (Always, Eventually)) else None
        pred = inner.child if isinstance(inner, Not) else inner
        if isinstance(pred, InRegion):
            d = regions[pred.region].signed_distance(trace[pred.body]) * (-1 if isinstance(inner, Not) else 1)
            a, b = (round(part.a_s / dt), min(round(part.b_s / dt), len(d) - 1))
            k = a + int(np.argmin(d[a:b + 1]) if isinstance(part, Always) else np.argmax(d[a:b + 1]))
            row.update(worst_s=k * dt, body=pred.body, region=pred.region, negated=isinstance(inner, Not),
                       window=(part.a_s, part.b_s), kind=type(part).__name__)
        out.append(row)
    return out


def switches_text(scenario, plan, after_s: float) -> str:
    """The plan's side switches after ``after_s``: who must get round what, with the time it has and needs."""
    unflyable = {(sw.robot, sw.object, sw.t2_s) for sw in unflyable_side_switches(plan, scenario, after_s)}
    parts = []
    for sw in side_switches(plan, scenario, after_s):
        parts.append(f"{sw.robot} must get round {sw.object} between its impacts at {sw.t1_s:.2f} and {sw.t2_s:.2f} "
                     f"({sw.t2_s - max(sw.t1_s, after_s):.1f} s left, at least {sw.needed_s:.1f} s needed"
                     f"{', NO TIME' if (sw.robot, sw.object, sw.t2_s) in unflyable else ''})")
    return "; ".join(parts) or "none"


def _reading(value: float | None) -> str:
    return "nothing" if value is None else f"{value:.3f}"


def fmt_v(v) -> str:
    return f"({v[0]:+.3f}, {v[1]:+.3f})"


@dataclass
class Contact:
    """One reported contact, with what the expert had planned and asked for it (robot-object pairs)."""

    t_s: float
    a: str
    b: str
    robot: str | None
    obj: str | None
    object_before: np.ndarray | None
    object_after: np.ndarray | None
    planned: object | None  # the PlannedImpact the bookkeeping matched it to
    asked: AskedContact | None
    side_cos: float | None  # cos(asked normal, observed normal); < 0: hit from the wrong side
    start_side_m: float | None  # robot - object along the asked normal when the approach began; > 0: far side


def contacts(scenario, expert, result) -> list[Contact]:
    """Every reported contact as a :class:`Contact`, in time order."""
    robots, objects = {r.name for r in scenario.robots}, {o.name for o in scenario.objects}
    index = {b.name: i for i, b in enumerate(scenario.bodies)}
    asked = expert.selector.strategy.asked
    out = []
    for ev, imp in expert.book.matches:
        a, b = ev["a"], ev["b"]
        robot = next(iter({a, b} & robots), None)
        obj = next(iter({a, b} & objects), None)
        row = Contact(float(ev["time"]), a, b, robot, obj, None, None, imp, None, None, None)
        if obj is not None:
            side = {a: "a", b: "b"}
            row.object_before = np.asarray(ev[f"{side[obj]}_velocity_before"], float)
            row.object_after = np.asarray(ev[f"{side[obj]}_velocity_after"], float)
        if robot is not None and obj is not None and imp is not None:
            ask = asked.get((robot, obj, round(imp.time_s, 6)))
            if ask is not None:
                dv = row.object_after - row.object_before
                row.asked = ask
                row.side_cos = float(dv @ ask.normal / max(np.linalg.norm(dv), 1e-12))
                k0 = int(round(ask.first_t_s / scenario.control_period_s))
                rel = result.positions[k0, index[robot]] - result.positions[k0, index[obj]]
                row.start_side_m = float(rel @ ask.normal)
        out.append(row)
    return out


def story(scenario, expert, record: EpisodeRecord, result, true_restitution: float) -> list[str]:
    """The impact-by-impact story (lines of text); see the module docstring."""
    lines = []
    events = [(c.t_s, 0, c) for c in contacts(scenario, expert, result)]
    events += [(rec.time_s, 1, rec) for rec in (expert.mission.records if expert.mission is not None else [])]
    plan_at = {round(t, 6): p for t, p in record.plans[1:]}
    estimates = list(record.estimates)
    offline = record.plans[0][1]
    lines.append(f"offline plan: rho {offline.robustness:.3f} m, {len(offline.impacts)} impacts, side switches: "
                 + switches_text(scenario, offline, -np.inf))
    for k, imp in enumerate(offline.impacts, 1):
        lines.append(f"  I{k} t={imp.time_s:6.2f} {imp.robot}-{imp.object} at ({imp.position[0]:.2f}, "
                     f"{imp.position[1]:.2f}): object {fmt_v(imp.object_velocity_before)} -> "
                     f"{fmt_v(imp.object_velocity_after)}")
    lines.append(f"simulator restitution {true_restitution:.2f} (scenario file {scenario.restitution:.2f})")
    for t, _, item in sorted(events, key=lambda e: (e[0], e[1])):
        if isinstance(item, Contact):
            c = item
            if c.robot is None or c.obj is None:
                lines.append(f"t={t:6.2f} contact {c.a}-{c.b}"
                             + (f": object {fmt_v(c.object_before)} -> {fmt_v(c.object_after)}" if c.obj else ""))
                continue
            if c.planned is None:
                lines.append(f"t={t:6.2f} contact {c.robot}-{c.obj} UNPLANNED: object {fmt_v(c.object_before)} -> "
                             f"{fmt_v(c.object_after)}")
                continue
            head = (f"t={t:6.2f} contact {c.robot}-{c.obj} = planned impact at {c.planned.time_s:.2f} "
                    f"({t - c.planned.time_s:+.2f} s): object {fmt_v(c.object_before)} -> {fmt_v(c.object_after)}")
            if c.asked is not None:
                ask = c.asked
                where = "on the FAR side of" if c.start_side_m > 0 else "on the contact side of"
                head += (f"\n          asked {fmt_v(ask.object_velocity_after)} with e={ask.restitution:.2f}: error "
                         f"{np.linalg.norm(c.object_after - ask.object_velocity_after):.3f} m/s; side cos "
                         f"{c.side_cos:+.2f}{' (WRONG SIDE)' if c.side_cos < 0 else ''}; when its approach began "
                         f"(t={ask.first_t_s:.1f} s) the robot was {where} the object")
            lines.append(head)
            while estimates and estimates[0][0] <= t + 1e-9:
                _, r, o, mean, std, verdict = estimates.pop(0)
                lines.append(f"          identified e({r}-{o}) = {mean:.3f} +- {std:.3f}" + (
                    "" if verdict is None else f" ({'in use' if verdict[0] else 'file value kept'}, "
                                               f"{verdict[1]}; this impact read {verdict[2]:.3f} from "
                                               f"the object, {_reading(verdict[3])} from the robot)"))
        else:
            rec = item
            lines.append(f"t={t:6.2f} mission check: predicted rho {rec.predicted_robustness:+.3f} < threshold "
                         f"{rec.threshold_m:.3f} -> {rec.status}"
                         + (f" (new plan rho {rec.new_robustness:+.3f}, solve {rec.solve_s:.1f} s"
                            + (f", {rec.impacts_added:+d} impacts" if rec.status.startswith("accepted") else "")
                            + ")" if rec.new_robustness is not None else ""))
            new = plan_at.get(round(t, 6))
            if new is not None:
                for imp in (i for i in new.impacts if i.time_s > t):
                    lines.append(f"          new impact t={imp.time_s:6.2f} {imp.robot}-{imp.object} at "
                                 f"({imp.position[0]:.2f}, {imp.position[1]:.2f}): object "
                                 f"{fmt_v(imp.object_velocity_before)} -> {fmt_v(imp.object_velocity_after)}")
                lines.append("          side switches: " + switches_text(scenario, new, t))
            if rec.unreachable:
                lines.append("          predicted unreachable (dropped from the prediction): "
                             + "; ".join(rec.unreachable))
    station = expert.mission.station if expert.mission is not None else None
    for trim in (station.records if station is not None else []):
        lines.append(f"t={trim.time_s:6.2f} station keeping {trim.goal} by {trim.robot}: drift margin "
                     f"{trim.drift_margin_m:+.3f} m -> {trim.status}"
                     + (f" (trim rho {trim.new_robustness:+.3f}, {trim.impacts_added:+d} impacts, {trim.planner}"
                        + (f", delta {trim.delta_mps:.4f} m/s" if trim.delta_mps is not None else "") + ")"
                        if trim.new_robustness is not None else "")
                     + (f"; the object's error {trim.observed_error_mps:.4f} m/s"
                        if trim.observed_error_mps is not None else ""))
    if expert.mission is not None:
        m = expert.mission.report()
        lines.append(f"mission monitor: {m['checks']} checks, {m['unreachable']} of them found a pending impact "
                     f"unreachable; {m['attempts']} re-plan attempts, {m['replans']} accepted; "
                     f"{m['settled']} kept a settled success")
    lines.append(f"result: robustness {result.robustness:+.3f} m, success {result.success}; "
                 f"unplanned contacts {dict(sorted(expert.book.unplanned.items())) or 'none'}")
    for row in task_parts(scenario, result.positions, scenario.control_period_s):
        worst = f", worst at t={row['worst_s']:.1f} s" if row["worst_s"] is not None else ""
        lines.append(f"  {row['part']}: {row['robustness']:+.3f} m{worst}")
    return lines


# --------------------------------------------------------------------------------------------- plot
def plot(scenario, record: EpisodeRecord, expert, result, path: str, title: str = "") -> None:
    """xy view (planned vs flown, contacts, re-plans) and each object's distance to its region over time."""
    from matplotlib.figure import Figure

    from impact_env.transport.plotting import DPI, draw_scenario
    from planners.plan.plotting import _colours

    colours = _colours(scenario)
    names = [b.name for b in scenario.bodies]
    index = {n: i for i, n in enumerate(names)}
    offline, final = record.plans[0][1], record.plans[-1][1]
    parts = [p for p in task_parts(scenario, result.positions, scenario.control_period_s)
             if p.get("body") in {o.name for o in scenario.objects} and not p["negated"]]
    fig = Figure(figsize=(13, 6.2), layout="constrained")
    grid = fig.add_gridspec(max(1, len(parts)), 2, width_ratios=[1.15, 1])
    ax = fig.add_subplot(grid[:, 0])
    draw_scenario(scenario, ax)
    legend = ax.get_legend()
    if legend is not None:
        legend.remove()
    t_plan = np.linspace(0.0, offline.tf_s, 800)
    for name in names:
        c = colours[name]
        ax.plot(*offline.position(name, t_plan).T, ":", color=c, lw=1.2)
        if final is not offline:
            t0 = record.plans[-1][0]
            tt = t_plan[t_plan >= t0]
            ax.plot(*final.position(name, tt).T, "--", color=c, lw=1.1)
        ax.plot(*result.positions[:, index[name]].T, "-", color=c, lw=1.8, label=f"{name} flown")
    dt = scenario.control_period_s
    shown = set()
    rows = contacts(scenario, expert, result)
    for c in rows:
        k = min(int(round(c.t_s / dt)), len(result.positions) - 1)
        if c.obj is None:  # a robot against a wall, an obstacle or another robot
            if c.robot is not None:
                label = "robot contact (wall, obstacle, robot)"
                ax.plot(*result.positions[k, index[c.robot]], ls="", marker="x", ms=7, color="k", zorder=9,
                        label=None if label in shown else label)
                shown.add(label)
            continue
        p = result.positions[k, index[c.obj]]
        if c.robot is None or c.planned is None:
            label, style = ("unplanned object contact (robot, wall)", dict(marker="X", ms=9, color="k"))
        elif c.side_cos is not None and c.side_cos < 0:
            label, style = ("planned impact, hit from the wrong side", dict(marker="X", ms=11, color="red", mec="k",
                                                                          mew=0.5))
        else:
            label, style = ("planned impact (flown)", dict(marker="*", ms=13, color="red", mec="k", mew=0.5))
        ax.plot(*p, ls="", zorder=9, label=None if label in shown else label, **style)
        shown.add(label)
        ax.annotate(f"{c.t_s:.1f}", p, xytext=(5, 5), textcoords="offset points", fontsize=7)
    for rec in (expert.mission.records if expert.mission is not None else []):
        k = int(round(rec.time_s / dt))
        accepted = rec.status.startswith("accepted")
        label = "mission re-plan accepted" if accepted else "mission re-plan kept the plan"
        for o in scenario.objects:
            ax.plot(*result.positions[k, index[o.name]], ls="", marker="D", ms=6, zorder=9,
                    color="tab:green" if accepted else "0.6", mec="k", mew=0.5,
                    label=None if label in shown else label)
            shown.add(label)
    ax.plot([], [], ":", color="0.3", label="offline plan")
    if final is not offline:
        ax.plot([], [], "--", color="0.3", label=f"last re-plan (from t={record.plans[-1][0]:.1f} s)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7)
    ax.set_title("planned vs flown")
    times = result.times_s
    regions = scenario.region_map()
    for row, part in enumerate(parts):
        a2 = fig.add_subplot(grid[row, 1])
        body, region = part["body"], part["region"]
        a2.plot(times, regions[region].signed_distance(result.positions[:, index[body]]), "-",
                color=colours[body], lw=1.8, label="flown")
        a2.plot(times, regions[region].signed_distance(offline.position(body, times)), ":", color="0.3",
                label="offline plan")
        if final is not offline:
            a2.plot(times, regions[region].signed_distance(final.position(body, times)), "--", color="0.3",
                    label="last re-plan")
        a2.axvspan(*part["window"], color="tab:green", alpha=0.12, label=f"{part['kind']} window")
        a2.axhline(0.0, color="k", lw=0.6)
        for c in rows:
            if body in (c.a, c.b):
                a2.axvline(c.t_s, color="red" if c.planned is not None else "k", ls="-", lw=0.6, alpha=0.6)
        for rec in (expert.mission.records if expert.mission is not None else []):
            a2.axvline(rec.time_s, color="tab:green" if rec.status.startswith("accepted") else "0.6", ls="--",
                       lw=0.8)
        a2.set_ylabel(f"in({body}, {region})\n(m, + inside)", fontsize=8)
        a2.set_title(f"{part['part']}: {part['robustness']:+.3f} m", fontsize=8)
        a2.grid(alpha=0.3)
        if row == 0:
            a2.legend(fontsize=7, loc="lower left")
    if parts:
        a2.set_xlabel("time (s); contacts: planned red, other black; re-plans dashed")
    fig.suptitle(f"{title or scenario.name}: flown robustness {result.robustness:+.3f} m (offline plan "
                 f"{offline.robustness:.3f} m)")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)


# ---------------------------------------------------------------------------------------------- main
def fly(scenario_name: str, stack: str, axis: str, level: float, seed: int, plan_file: Path | None = None,
        config=None):
    """Fly one cell's episode with recording; returns (scenario, expert, record, result, env options)."""
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.online.bookkeeping import ImpactBook
    from planners.online.reference import PlanContact, held_goal_regions
    from planners.plan import Plan

    scenario = load_scenario(scenario_name)
    plan = Plan.load(plan_file or plan_path(RESULTS, scenario.name))
    config = config or expert_config(stack)
    held = held_goal_regions(scenario) if config.aim_final_position and config.aim_held_goal_center else {}
    strategy = RecordingStrategy(PlanContact(aim_final_position=config.aim_final_position, held=held))
    expert = Expert(scenario, plan=plan, config=config, strategy=strategy)
    expert.book = recording_book(ImpactBook)(expert.book.impacts, expert.book.tolerance_s)
    options = env_options(scenario, axis, level, seed)
    recorder = Recorder(expert)
    result = run_episode(TransportEnv(scenario, **options), recorder, seed=seed)
    return scenario, expert, recorder.record, result, options


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_cell_arguments(ap, seed=True)
    ap.add_argument("--plan", type=Path, help="plan file (default: the benchmark's cached plan of the scenario)")
    ap.add_argument("--plot", help="write the figure to this PNG")
    ap.add_argument("--significance", type=float, metavar="K",
                    help="turn identification's significance test on at k = K standard errors "
                         "(IdentificationConfig.significance)")
    ap.add_argument("--conjunct-weight", type=float, metavar="W",
                    help="the mission re-plans' weight on each conjunct's own robustness "
                         "(MissionConfig.conjunct_weight)")
    args = ap.parse_args(argv)
    stack = args.stack
    config = expert_config(stack, args.allow_side_switches)
    if args.significance is not None:
        config = dataclasses.replace(config, identification=dataclasses.replace(
            config.identification, significance=args.significance))
    if args.conjunct_weight is not None and config.mission is not None:
        config = dataclasses.replace(config, mission=dataclasses.replace(
            config.mission, conjunct_weight=args.conjunct_weight))
    scenario, expert, record, result, options = fly(args.scenario, stack, args.axis, args.level, args.seed,
                                                    args.plan, config)
    sig = "" if args.significance is None else f" / significance {args.significance:g}"
    print(f"{scenario.name} / {stack}{sig} / {args.axis} {args.level:g} / seed {args.seed}: env options {options}")
    true_e = options.get("restitution", scenario.restitution)
    print("\n".join(story(scenario, expert, record, result, true_e)))
    if args.plot:
        title = f"{scenario.name}, {stack}, {args.axis} {args.level:g} (e = {true_e:.2f}), seed {args.seed}"
        plot(scenario, record, expert, result, args.plot, title)
        print(f"figure: {args.plot}")


if __name__ == "__main__":
    main()
