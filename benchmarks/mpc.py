"""MPC benchmark: time per ``FreeflyerMPC.solve`` call in closed loop, per solver, horizon and case.

Each configuration flies its own closed loop of ``--solves`` control periods: episodes of 60 periods
(0.1 s), each from rest at a cold start (``reset()``), tracking a reference that accelerates at 0.1 m/s^2
to 0.2 m/s along +x. Cases:

- ``plain``: tracking only;
- ``impact``: an impact 3.0 s into the episode (post-impact 0.025 m/s, Eq. 5 with e = 0.75 and equal
  masses), as a replanner would move it: up to 3 cm beside the reference and with 2 cm/s of lateral
  pre-impact velocity, so the impact-node constraint is active. ``ImpactSpec`` whenever its node is within
  the horizon (0..N); the plant's velocity jumps at that instant and the reference continues at 0.025 m/s;
- ``keep-off``: a static disc 5-15 cm beside the line at x = 1.2 m must be kept 0.4 m away;
- ``head-on``: the same disc right on the line: a stress case (the robot must hold 0.4 m in front while
  the reference runs on through the disc, so tracking errors and multipliers grow all episode).

Every episode draws (seeded, the same draws for every configuration) a start offset of up to 5 cm and
0.1 rad, the disc's lateral offset in 5-15 cm and the impact's lateral offset in +-3 cm. The plant is the
MPC's own RK4 model (the solve time, not the physics, is measured). All configurations advance in lockstep
(one control period each, in turn), so load from other processes hits them alike; the
ipopt rows are the baseline (the paper's solver; it reports a 6 ms median). Times are wall-clock of the
whole ``solve()`` call, Python included. Fallback solvers are off (failures are the solver's own) except
in the ``sqp+ipopt`` rows, the default ``MPCConfig`` (sqp, ipopt when sqp fails). Usage:

    python -m benchmarks.mpc [--solves 2000] [--solvers sqp,fatrop,ipopt,sqp+ipopt] [--horizons 10,20]
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass, field

import numpy as np

from impact_env.transport.scenario import load_scenario
from planners.online.mpc import SOLVERS, AvoidSpec, FreeflyerMPC, ImpactSpec, MPCConfig, rk4_step

DT = 0.1
EPISODE = 60
HIT_STEP, V_PRE, V_POST = 30, 0.2, 0.025
CASES = ("plain", "impact", "keep-off", "head-on")
SOLVER_ROWS = (*SOLVERS, "sqp+ipopt")


def reference(t: np.ndarray, impact: bool) -> np.ndarray:
    """(len(t), 4) [x, y, vx, vy]: accelerate at 0.1 m/s^2 to 0.2 m/s, then cruise; after an impact
    (``impact``, at t = 3 s) continue at the post-impact speed."""
    ramp = np.minimum(t, 2.0)
    x = 0.05 * ramp ** 2 + V_PRE * np.maximum(t - 2.0, 0.0)
    v = np.minimum(0.1 * t, V_PRE)
    if impact:
        t_hit = HIT_STEP * DT
        x_hit = 0.05 * 4.0 + V_PRE * (t_hit - 2.0)
        after = t > t_hit + 1e-9
        x = np.where(after, x_hit + V_POST * (t - t_hit), x)
        v = np.where(after, V_POST, v)
    return np.stack([x, 0 * t, v, 0 * t], axis=1)


@dataclass
class Loop:
    """One configuration's closed loop and its measurements."""

    solver: str
    horizon: int
    case: str
    mpc: FreeflyerMPC
    state: np.ndarray = field(default_factory=lambda: np.zeros(6))
    step: int = 0
    times_ms: list[float] = field(default_factory=list)
    iterations: list[int] = field(default_factory=list)
    quality_m: list[float] = field(default_factory=list)
    impact_error: float = 0.0
    episode: np.ndarray = field(default_factory=lambda: np.zeros(5))

    def advance(self) -> None:
        """Solve once, apply the wrench to the RK4 plant for one period, record."""
        n, k = self.horizon, self.step % EPISODE
        if k == 0:
            self.mpc.reset()
            # start offset (x, y, heading), disc and impact lateral offsets: the same for every configuration
            rng = np.random.default_rng(self.step // EPISODE)
            self.episode = rng.uniform([-0.05, -0.05, -0.1, 0.05, -0.03], [0.05, 0.05, 0.1, 0.15, 0.03])
            self.state = np.array([self.episode[0], self.episode[1], self.episode[2], 0.0, 0.0, 0.0])
        disc = np.array([1.2, 0.0 if self.case == "head-on" else self.episode[3]])
        t = DT * (k + np.arange(n + 1))
        impact = avoid = None
        if self.case == "impact" and 0 <= HIT_STEP - k <= n:
            x_hit = reference(np.array([HIT_STEP * DT]), True)[0, 0]
            impact = ImpactSpec(HIT_STEP - k, (x_hit, self.episode[4]), (V_PRE, 0.02), (V_POST, 0.0))
        if self.case in ("keep-off", "head-on"):
            avoid = AvoidSpec(np.tile(disc, (n + 1, 1)), 0.4, np.ones(n + 1, dtype=bool))
        result = self.mpc.solve(self.state, reference(t, self.case == "impact"), impact=impact, avoid=avoid)
        self.times_ms.append(result.solve_ms)
        self.iterations.append(result.iterations)
        if impact is not None and impact.step == 1:
            self.impact_error = max(self.impact_error, result.impact_error)
        if k + 1 == HIT_STEP and self.case == "impact":  # the collision, as the simulator would apply it
            self.state = rk4_step(self.state, result.wrench, self.mpc.robot, DT)
            self.state[3:5] = (V_POST, 0.0)
        else:
            self.state = rk4_step(self.state, result.wrench, self.mpc.robot, DT)
        if self.case in ("keep-off", "head-on"):
            self.quality_m.append(float(np.hypot(*(self.state[0:2] - disc))))
        elif k + 1 >= 20 and not (self.case == "impact" and HIT_STEP - 5 <= k + 1 <= HIT_STEP + 10):
            ref_next = reference(np.array([DT * (k + 1)]), self.case == "impact")[0]
            self.quality_m.append(float(np.hypot(*(self.state[0:2] - ref_next[0:2]))))
        self.step += 1

    def row(self) -> str:
        t = np.array(self.times_ms)
        it = np.array(self.iterations)
        if self.case in ("keep-off", "head-on"):
            quality = f"closest {min(self.quality_m):.3f} m"
        else:
            quality = f"tracking {1000 * max(self.quality_m):.1f} mm"
        if self.case == "impact":
            quality += f", impact node {1000 * self.impact_error:.2f} mm"
        return (f"| {self.solver} | {self.horizon} | {self.case} | {np.median(t):.2f} | {np.percentile(t, 99):.2f} | "
                f"{t.max():.1f} | {np.median(it):.0f} / {it.max()} | {self.mpc.failures} ({self.mpc.fallbacks}) | "
                f"{quality} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--solves", type=int, default=2000, help="closed-loop solves per configuration")
    parser.add_argument("--solvers", default=",".join(SOLVER_ROWS), help=f"comma-separated subset of {SOLVER_ROWS}")
    parser.add_argument("--horizons", default="10,20", help="comma-separated horizons N")
    args = parser.parse_args()
    solvers = [s for s in args.solvers.split(",") if s]
    unknown = sorted(set(solvers) - set(SOLVER_ROWS))
    if unknown:
        parser.error(f"unknown solver(s) {unknown}; choose from {', '.join(SOLVER_ROWS)}")
    horizons = [int(h) for h in args.horizons.split(",") if h]
    if args.solves < 1 or any(h < 2 for h in horizons):
        parser.error("--solves must be >= 1 and every horizon >= 2")

    robot = load_scenario("throw_and_catch_exp").robots[0]
    def config(solver: str, n: int) -> MPCConfig:
        if solver == "sqp+ipopt":
            return MPCConfig(horizon=n)  # the default: sqp, ipopt as fallback
        return MPCConfig(horizon=n, solver=solver, fallback_solver=None)

    loops = [Loop(s, n, case, FreeflyerMPC(robot, config(s, n))) for s in solvers for n in horizons for case in CASES]
    for _ in range(args.solves):
        for loop in loops:
            loop.advance()

    print(f"{args.solves} closed-loop solves per row ({args.solves // EPISODE} episodes of {EPISODE}, each from a "
          "cold start); solve() wall time in ms; iterations median / max of the solver that answered; "
          "quality: worst tracking error after 2 s (outside 0.5 s before to 1 s after an impact), worst "
          "|planned - predicted| impact state one node ahead, closest approach to the disc (0.4 m required)\n")
    print("| solver | N | case | median ms | p99 ms | max ms | iterations | failures (fallbacks) | quality |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for loop in loops:
        print(loop.row())
    print(f"\nmachine: {os.cpu_count()} CPUs (os.cpu_count()); load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
