"""Contacts that end in one substep take their post-impact noise in the scenario's order, whatever the heap.

Chipmunk calls the separate callbacks of the contacts that end in one substep in the order of a hash set keyed
by the shapes' C addresses, and the simulator drew the post-impact velocity noise in that order: at
two_objects' two simultaneous impacts (t = 28 s) the two draws went to one object or the other depending on
where malloc had put the shapes (tests/planners/expert/test_determinism.py flies those episodes).
"""

from __future__ import annotations

import numpy as np
import pymunk

from impact_env.transport.physics import World
from impact_env.transport.scenario import scenario_from_dict
from tests.helpers import two_body_dict


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
