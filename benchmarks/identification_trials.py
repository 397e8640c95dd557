"""Identification's two properties in seeded trials of simulator impacts, for every estimator option.

The expert's identification (:mod:`planners.online.identification`) must tell post-impact noise from a wrong
restitution. Each trial flies real impacts in the simulator (:class:`impact_env.transport.physics.World`):
a robot meets an object with a random approach (normal speed 5-30 cm/s from any side, a sideways slide of up
to 10 cm/s, the object drifting at up to 5 cm/s) while thrusting anywhere within its limits through the
contact, as the MPC may. Two properties, 300 trials each per row:

- **noise**: the simulator has the file's restitution and a uniform error in [-M, M] m/s per axis on the
  object's velocity after each impact (the env's ``impact_velocity_noise_mps``); 4 impacts on random pairs
  of 2 robots and 2 objects; a trial passes when every pair's restitution (the one the contact inverse uses)
  stays within 0.05 of the file's after every impact;
- **mismatch**: no noise, the simulator's restitution off by +-0.1 to 0.3; a trial passes when, after 2
  impacts of one pair, that pair's restitution is within 0.05 of the simulator's.

    python -m benchmarks.identification_trials [--trials 300] [--options bounded,significance=3,gaussian]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

NOISE_LEVELS_MPS = (0.005, 0.01, 0.02, 0.03)
MISMATCHES = (0.1, 0.2, 0.3)
TOLERANCE = 0.05
ROBOTS, OBJECTS = ("R1", "R2"), ("O1", "O2")
MASS_KG = 16.8  # every shipped scenario's robots and objects
THRUST_N = 2.8


def sim_impact(rng: np.random.Generator, restitution: float, noise_mps: float, robot: str = "R1",
               obj: str = "O1", time_s: float = 0.0) -> dict:
    """One robot-object contact in the simulator, as the env reports it in ``info["impacts"]``, renamed to
    the pair (``robot``, ``obj``). The bodies start a millimetre apart so that the contact begins in the
    first substep, the robot's random thrust held from then on; a draw whose contact does not end within 2 s
    (a nearly plastic one that the thrust keeps closed) is drawn again."""
    for _ in range(100):
        event = _try_impact(rng, restitution, noise_mps)
        if event is not None:
            names = {"R1": robot, "O1": obj}
            return {**event, "a": names[event["a"]], "b": names[event["b"]], "time": time_s}
    raise RuntimeError(f"no contact ended in 100 draws at restitution {restitution}")


def _try_impact(rng: np.random.Generator, restitution: float, noise_mps: float) -> dict | None:
    from impact_env.transport.physics import World
    from impact_env.transport.scenario import scenario_from_dict

    radius = 0.2
    angle = rng.uniform(-math.pi, math.pi)
    n = np.array([math.cos(angle), math.sin(angle)])
    t = np.array([-n[1], n[0]])
    v_object = rng.uniform(-0.05, 0.05, 2)
    v_robot = v_object + rng.uniform(0.05, 0.3) * n + rng.uniform(-0.1, 0.1) * t
    p_object = np.array([5.0, 5.0])
    p_robot = p_object - (2 * radius + 1e-3) * n
    body = {"mass_kg": MASS_KG, "radius_m": radius, "inertia_kgm2": 0.1594}
    scenario = scenario_from_dict({
        "name": "identification_trial", "restitution": restitution, "tf_s": 10.0, "control_period_s": 0.1,
        "substeps": 10, "task": "F[0,10] in(O1, goal)", "world": {"box": [0.0, 10.0, 0.0, 10.0]},
        "regions": [{"name": "goal", "box": [8.0, 9.0, 8.0, 9.0]}],
        "robots": [{"name": "R1", **body, "position_m": p_robot.tolist(), "velocity_mps": v_robot.tolist(),
                    "heading_rad": rng.uniform(-math.pi, math.pi), "thrust_limit_N": [THRUST_N, THRUST_N],
                    "torque_limit_Nm": 0.2}],
        "objects": [{"name": "O1", **body, "position_m": p_object.tolist(), "velocity_mps": v_object.tolist()}]})
    world = World(scenario, impact_velocity_noise_mps=noise_mps, rng=rng)
    thrust = tuple(rng.uniform(-THRUST_N, THRUST_N, 2))
    for _ in range(20):
        events = [e for e in world.step([(*thrust, 0.0)]) if {e.a, e.b} == {"R1", "O1"}]
        if events:
            return events[0].to_dict()
    return None


def make_identifier(option: str, restitution: float):
    """The expert's identifier for the file's ``restitution`` with the estimator ``option``: ``bounded``,
    ``significance=K`` or ``gaussian`` (``IdentificationConfig.estimator``), given each robot's largest
    acceleration as the expert gives it."""
    from planners.online.identification import IdentificationConfig, ImpactIdentifier

    masses = {name: MASS_KG for name in ROBOTS + OBJECTS}
    if option.startswith("significance="):
        config = IdentificationConfig(estimator="significance", significance=float(option.split("=")[1]))
    else:
        config = IdentificationConfig(estimator=option)
    accelerations = {name: math.hypot(THRUST_N, THRUST_N) / MASS_KG for name in ROBOTS}
    return ImpactIdentifier(restitution, masses, frozenset(ROBOTS), frozenset(OBJECTS), config, accelerations)


def noise_trial(rng: np.random.Generator, option: str, noise_mps: float, impacts: int = 4) -> bool:
    """One trial of the noise property (module docstring): True if it passes."""
    restitution = float(rng.uniform(0.35, 0.85))
    ident = make_identifier(option, restitution)
    for k in range(impacts):
        robot, obj = ROBOTS[rng.integers(2)], OBJECTS[rng.integers(2)]
        ident.observe([sim_impact(rng, restitution, noise_mps, robot, obj, float(k))])
        if any(abs(ident.restitution_for(r, o) - restitution) > TOLERANCE for r in ROBOTS for o in OBJECTS):
            return False
    return True


def mismatch_trial(rng: np.random.Generator, option: str, mismatch: float, impacts: int = 2) -> bool:
    """One trial of the mismatch property (module docstring): True if it passes."""
    restitution = float(rng.uniform(0.35, 0.85))
    sign = 1.0 if rng.uniform() < 0.5 else -1.0
    if not 0.0 <= restitution + sign * mismatch <= 1.0:
        sign = -sign
    true_e = restitution + sign * mismatch
    ident = make_identifier(option, restitution)
    for k in range(impacts):
        ident.observe([sim_impact(rng, true_e, 0.0, "R1", "O1", float(k))])
    return abs(ident.restitution_for("R1", "O1") - true_e) <= TOLERANCE


def pass_rates(option: str, trials: int, seed: int = 0) -> dict[str, float]:
    """Share of ``trials`` seeded trials passed, per noise level (``noise 0.02``) and per mismatch
    (``mismatch 0.2``); each row's trials draw from their own generator, seeded by ``seed`` and the row."""
    out = {}
    for k, level in enumerate(NOISE_LEVELS_MPS):
        rng = np.random.default_rng([seed, 1, k])
        out[f"noise {level:g}"] = sum(noise_trial(rng, option, level) for _ in range(trials)) / trials
    for k, mismatch in enumerate(MISMATCHES):
        rng = np.random.default_rng([seed, 2, k])
        out[f"mismatch {mismatch:g}"] = sum(mismatch_trial(rng, option, mismatch) for _ in range(trials)) / trials
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--options", default="bounded,significance=2,significance=3,significance=4,gaussian",
                        help="estimators to measure: bounded, significance=K, gaussian")
    args = parser.parse_args()
    options = [o for o in args.options.split(",") if o]
    rows = {option: pass_rates(option, args.trials, args.seed) for option in options}
    columns = list(next(iter(rows.values())))
    print(f"{args.trials} trials per cell, seed {args.seed}: share of trials within {TOLERANCE:g} of the "
          "file's restitution (noise, 4 impacts) or of the simulator's (mismatch, after 2 impacts)\n")
    print("| estimator | " + " | ".join(columns) + " |\n|---|" + "---:|" * len(columns))
    for option, rates in rows.items():
        print(f"| {option} | " + " | ".join(f"{100 * rates[c]:.1f}%" for c in columns) + " |")


if __name__ == "__main__":
    main()
