"""Same seed, same episode: whatever the process flew or planned before.

Two defects these tests pin down:

- the STL encoder memoised encodings by ``id()`` of formula nodes that it did not keep alive. The negation
  normal form builds new nodes for every conjunct (e.g. ``!in(R1, pillar)``); once a conjunct was encoded its
  nodes were freed, and a node of a later conjunct could be allocated at the same address and be given the
  earlier conjunct's encoding. Whether that happened depended on the heap, i.e. on what the process had done
  before, so a mission re-plan (and hence an episode) of two_objects could differ between a fresh process and
  a benchmark worker that had flown other seeds;
- chipmunk calls the separate callbacks of the contacts that end in one substep in the order of a hash set
  keyed by the shapes' C addresses, and the simulator drew the post-impact velocity noise in that order: at
  two_objects' two simultaneous impacts (t = 28 s) the two draws went to one object or the other depending on
  where malloc had put the shapes. It looked as if the expert changed the ``Plan`` it was given (an episode
  differed after another episode with the same plan); the plan was never changed, and the tests below check
  that too, with its arrays made read-only so that a write would raise.
"""

from __future__ import annotations

import dataclasses
import pickle
import re

import numpy as np
import pymunk
import pytest

from impact_env.geometry import ConvexPolygon
from impact_env.rollout import run_episode
from impact_env.stl import Always, InRegion
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.physics import World
from impact_env.transport.scenario import load_scenario, scenario_from_dict
from planners.expert import Expert, ExpertConfig
from planners.offline.milp.model import Model
from planners.offline.milp.stl_encoding import STLEncoder
from planners.offline.milp.trajectories import Grid
from planners.offline.solvers import solve
from planners.offline.spatially_robust import PlannerConfig, build_model
from planners.plan import Plan
from tests.helpers import two_body_dict
from tests.paths import DATA

SQUARE = ConvexPolygon.from_vertices([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
INSIDE, OUTSIDE = (0.5, 0.3), (1.5, 0.5)  # body A 0.3 m inside the square, body B 0.5 m outside


def _encoder() -> tuple[Model, STLEncoder]:
    model = Model()
    points = {name: (model.add_var(x, x), model.add_var(y, y)) for name, (x, y) in (("A", INSIDE), ("B", OUTSIDE))}
    box = (-2.0, 3.0, -2.0, 3.0)
    return model, STLEncoder(model, Grid(1, 1.0), lambda body, k: [points[body]], {"A": box, "B": box},
                             {"sq": SQUARE})


def _same_address_as(dead_id: int, make):
    """A new object from ``make()``, at the address ``dead_id`` if CPython's allocator hands it out again
    within a few thousand allocations (it normally does at once), else the last one made."""
    keep = []
    for _ in range(5000):
        obj = make()
        if id(obj) == dead_id:
            return obj
        keep.append(obj)  # held, so that the allocator moves on to other addresses
    return obj


def test_a_formula_freed_after_encoding_does_not_lend_its_encoding_to_a_new_one():
    model, encoder = _encoder()
    first = Always(0.0, 1.0, InRegion("A", "sq"))
    r_a = encoder.encode(first)
    dead = id(first.child)
    del first  # the caller drops its formula, as the planner drops each conjunct's negation normal form
    r_b = encoder.encode(Always(0.0, 1.0, _same_address_as(dead, lambda: InRegion("B", "sq"))))
    model.set_objective(r_a + r_b, maximize=True)
    x = solve(model, "highs").x
    assert r_a.value(x) == pytest.approx(0.3, abs=1e-7)
    assert r_b.value(x) == pytest.approx(-0.5, abs=1e-7)  # B's own distance, not A's +0.3


def test_the_upper_bound_of_a_freed_robustness_variable_is_not_inherited():
    model, encoder = _encoder()
    r = encoder.encode(Always(0.0, 1.0, InRegion("A", "sq")))
    assert encoder.upper_bound(r) < encoder.bound  # A's predicate can reach at most the square's inradius
    dead = id(r)
    del r
    other = _same_address_as(dead, lambda: model.add_var(-1.0, 1.0))
    assert encoder.upper_bound(other) == encoder.bound  # a stranger to the encoder: only the scene's bound


def test_each_pillar_conjunct_of_two_objects_has_its_own_robustness_variables():
    built = build_model(load_scenario("two_objects"), PlannerConfig())
    m = built.model
    groups = sorted({g for g in m.row_groups if g.startswith("task:") and "pillar" in g})
    assert len(groups) == 2
    for group in groups:
        robot = re.search(r"!in\((R\d), pillar\)", group).group(1)
        used = {m.col_names[i] for row, g in zip(m.rows, m.row_groups) if g == group for i in row[0]}
        names = {n for n in used if n.startswith("!in(")}
        assert names and all(n.startswith(f"!in({robot},pillar)@") for n in names), (group, sorted(names))


COMBINED = {"initial_position_noise_m": 0.10, "thrust_noise": 0.10}  # the robustness benchmark's combined condition


def _actions(expert: Expert, seed: int) -> np.ndarray:
    sc = expert.scenario
    restitution = float(np.clip(sc.restitution + (0.2 if seed % 2 else -0.2), 0.0, 1.0))
    env = TransportEnv(sc, restitution=restitution, **COMBINED)
    obs, info = env.reset(seed=seed)
    expert.reset()
    out, done = [], False
    while not done:
        out.append(expert.act(obs, info))
        obs, _, terminated, truncated, info = env.step(out[-1])
        done = terminated or truncated
    return np.array(out)


def _fresh_and_used(name: str, seed: int, before: list[int], config: ExpertConfig) -> None:
    sc = load_scenario(name)
    used = Expert(sc, config=config)
    for s in before:
        _actions(used, s)
    again = _actions(used, seed)
    fresh = _actions(Expert(sc, plan=used.offline_plan, config=config), seed)
    assert again.shape == fresh.shape
    assert np.array_equal(again, fresh), f"first difference at step {np.flatnonzero((again != fresh).any(1))[0]}"


def test_a_used_and_reset_expert_flies_a_seed_as_a_fresh_one():
    """The benchmarks keep one expert per worker and reset it between episodes: the episode must not depend
    on what it flew before (every part on, mission re-plans included)."""
    _fresh_and_used("throw_and_catch_exp", 2, [0, 1], ExpertConfig())


@pytest.mark.slow
@pytest.mark.parametrize("config", [ExpertConfig(), ExpertConfig.paper(mission_replanning=True)],
                         ids=["all", "+mission"])
def test_two_objects_episodes_do_not_depend_on_the_episodes_before(config):
    """two_objects re-plans its mission in most combined-condition episodes: the scenario the defect hit."""
    _fresh_and_used("two_objects", 3, [0, 1, 2], config)


# ----------------------------------------------------------------------- contacts that end in one substep
def _two_pairs() -> World:
    """R1 -> O1 and R2 -> O2, the same head-on impact 4 m apart: both contacts end in the same substep."""
    data = two_body_dict(e=0.75, robot_pos=(2.0, 3.0), object_pos=(4.0, 3.0), control_period_s=0.01, substeps=1)
    data["robots"].append({**data["robots"][0], "name": "R2", "position_m": [2.0, 7.0]})
    data["objects"].append({**data["objects"][0], "name": "O2", "position_m": [4.0, 7.0]})
    return World(scenario_from_dict(data), impact_velocity_noise_mps=0.05, rng=np.random.default_rng(7))


def test_contacts_that_end_in_one_substep_take_their_noise_in_the_scenario_order():
    """Whatever addresses the shapes got, the first draw goes to R1's impact and the second to R2's (the
    scenario's order), on top of Eq. (5). The worlds are kept alive and the heap is moved between them, so
    the shapes of each land elsewhere; chipmunk's own order changed from world to world before the fix."""
    v_object = (1 + 0.75) / 2 * 0.3  # Eq. (5), equal masses, object at rest
    first, second = np.random.default_rng(7).uniform(-0.05, 0.05, (2, 2))
    held = []
    for k in range(30):
        world = _two_pairs()
        held += [world, [pymunk.Circle(None, 1.0) for _ in range(1 + 5 * k)]]
        events = []
        for _ in range(2000):
            events += world.step([(0.0, 0.0, 0.0)] * 2)
            if len(events) >= 2:
                break
        assert [(e.a, e.b) for e in events] == [("R1", "O1"), ("R2", "O2")], f"world {k}"
        assert events[0].time_s == events[1].time_s and events[0].duration_s == events[1].duration_s
        np.testing.assert_allclose(events[0].velocity_after("O1"), (v_object + first[0], first[1]), atol=1e-9)
        np.testing.assert_allclose(events[1].velocity_after("O2"), (v_object + second[0], second[1]), atol=1e-9)
        assert tuple(world.bodies[2].velocity) == events[0].velocity_after("O1")  # the body flies the draw
        assert tuple(world.bodies[3].velocity) == events[1].velocity_after("O2")


# ------------------------------------------------- one Plan object, new or reused experts, impact noise
# the robustness benchmark's cached plan (plan_spatially_robust's, fingerprint c5fd64727b18; a copy of
# results/robustness/plans/two_objects.json)
TWO_OBJECTS_PLAN = DATA / "plans" / "robustness" / "two_objects.json"
IMPACT_NOISE = {"impact_velocity_noise_mps": 0.02}


def _frozen(plan: Plan) -> Plan:
    """The plan with every array read-only (in place), so that an expert that wrote into it would raise."""
    def walk(x):
        if isinstance(x, np.ndarray):
            x.flags.writeable = False
        elif dataclasses.is_dataclass(x):
            for f in dataclasses.fields(x):
                walk(getattr(x, f.name))
        elif isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                walk(v)

    walk(plan)
    return plan


def _arrays(plan: Plan) -> list[np.ndarray]:
    out = [s.control_points for b in plan.bodies.values() for s in b.segments]
    for f in plan.funnels.values():
        out += [f.position_halfwidth_m, f.velocity_halfwidth_mps]
    return [np.array(a, copy=True) for a in out]


def _same_episodes(name: str, plan: Plan, config, seed: int, before: list[int], env_kwargs: dict) -> Expert:
    """``seed`` flown by a fresh expert, by a new expert after ``before`` were flown with the same Plan object,
    and by one expert reused (reset by run_episode) over ``before``: the same trajectory, bit for bit; the
    plan unchanged after all of it. Returns the fresh expert, as it ended its episode."""
    sc = load_scenario(name)
    plan = _frozen(plan)
    fingerprint, blob, arrays = plan.fingerprint(), pickle.dumps(plan), _arrays(plan)
    held = []  # every env is kept and the heap moved, so that each episode's shapes land at new addresses

    def fly(expert: Expert, s: int):
        held.append([pymunk.Circle(None, 1.0) for _ in range(1 + 7 * len(held))])
        held.append(TransportEnv(sc, **env_kwargs))
        return run_episode(held[-1], expert, seed=s)

    first = Expert(sc, plan=plan, config=config)
    fresh = fly(first, seed)
    reused = Expert(sc, plan=plan, config=config)
    for s in before:
        fly(reused, s)
    runs = {"after other episodes": fly(Expert(sc, plan=plan, config=config), seed), "reused": fly(reused, seed)}
    for label, run in runs.items():
        assert run.robustness == fresh.robustness, label
        same = (run.positions == fresh.positions).all(axis=(1, 2))
        assert same.all(), f"{label}: first difference at step {np.flatnonzero(~same)[0]}"
        assert run.impacts == fresh.impacts, label
    assert plan.fingerprint() == fingerprint and pickle.dumps(plan) == blob
    assert all(np.array_equal(a, b) for a, b in zip(_arrays(plan), arrays))
    return first


def test_the_papers_expert_flies_a_seed_alike_whatever_flew_the_plan_before():
    """two_objects' seed 1 under 0.02 m/s impact noise: 0.14604 m fresh, 0.14716 m when the draws at its two
    simultaneous impacts at t = 28 s were swapped (in about one process in two before the fix)."""
    _same_episodes("two_objects", Plan.load(TWO_OBJECTS_PLAN), ExpertConfig.paper(), 1, [0], IMPACT_NOISE)


def test_the_full_expert_reused_over_seeds_flies_a_seed_as_a_fresh_one_under_impact_noise():
    _same_episodes("two_objects", Plan.load(TWO_OBJECTS_PLAN), ExpertConfig(), 1, [0], IMPACT_NOISE)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["two_objects", "ping_pong_stop"])
@pytest.mark.parametrize("config", [ExpertConfig.paper(), ExpertConfig()], ids=["paper", "all"])
def test_seeds_fly_alike_whatever_flew_the_plan_before(name, config):
    sc = load_scenario(name)
    plan = Plan.load(TWO_OBJECTS_PLAN) if name == "two_objects" else Expert(sc).offline_plan
    for seed in (2, 3):
        _same_episodes(name, plan, config, seed, [0, 1], {"impact_velocity_noise_mps": 0.03})


@pytest.mark.slow
def test_an_impact_robust_plan_is_left_as_it_was_given_by_the_contingency_path_and_mission_replanning():
    """The corridor's IR plan flown by its copies (CopyContact) under impact noise beyond its delta, restitution
    mismatch and start offsets, so that a mission re-plan splices the plan: same episodes, plan unchanged."""
    from planners.offline.impact_robust import plan_impact_robust
    from planners.online.contingency import CopyContact

    plan = plan_impact_robust(load_scenario("corridor"))
    fresh = _same_episodes("corridor", plan, ExpertConfig(), 0, [1],
                           {"impact_velocity_noise_mps": 0.05, "restitution": 0.3, "initial_position_noise_m": 0.1})
    assert isinstance(fresh.selector.strategy, CopyContact)
    assert fresh.report()["mission"]["replans"] >= 1  # the splice was flown
