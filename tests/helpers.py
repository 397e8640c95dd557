"""Small scenario builders and checks shared by the tests."""

from __future__ import annotations

import copy

from impact_env.transport.scenario import Scenario, scenario_from_dict

FREEFLYER = {"mass_kg": 16.8, "radius_m": 0.2, "inertia_kgm2": 0.1594}


def two_body_dict(*, e: float = 0.75, m_robot: float = 16.8, m_object: float = 16.8,
                  robot_pos=(2.0, 5.0), robot_vel=(0.3, 0.0), object_pos=(4.0, 5.0), object_vel=(0.0, 0.0),
                  r_robot: float = 0.2, r_object: float = 0.2, heading: float = 0.0, control_period_s: float = 0.1,
                  substeps: int = 10, box=(0.0, 10.0, 0.0, 10.0)) -> dict:
    """A robot and an object in a large empty box, no velocity bounds (so any speed is allowed)."""
    return {
        "name": "two_body", "restitution": e, "tf_s": 20.0, "control_period_s": control_period_s,
        "substeps": substeps, "task": "F[0,10] in(O1, goal)",
        "world": {"box": list(box)},
        "regions": [{"name": "goal", "box": [8.0, 9.0, 4.0, 6.0]}],
        "robots": [{"name": "R1", "mass_kg": m_robot, "radius_m": r_robot, "inertia_kgm2": 0.1594,
                    "position_m": list(robot_pos), "velocity_mps": list(robot_vel), "heading_rad": heading,
                    "thrust_limit_N": [2.8, 2.8], "torque_limit_Nm": 0.2}],
        "objects": [{"name": "O1", "mass_kg": m_object, "radius_m": r_object, "inertia_kgm2": 0.1594,
                     "position_m": list(object_pos), "velocity_mps": list(object_vel)}],
    }


def two_body(**kwargs) -> Scenario:
    return scenario_from_dict(two_body_dict(**kwargs))


def modified(data: dict, path: str, value) -> dict:
    """Copy of a scenario dict with one field (dotted path, list indices allowed) replaced or deleted."""
    out = copy.deepcopy(data)
    keys = [int(k) if k.isdigit() else k for k in path.split(".")]
    node = out
    for k in keys[:-1]:
        node = node[k]
    if value is _DELETE:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return out


_DELETE = object()
DELETE = _DELETE


def one_line_error(argv: list[str], capsys) -> str:
    """What ``impact-env argv`` writes to stderr; it must fail with exit code 2 and no traceback."""
    from impact_env.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err
