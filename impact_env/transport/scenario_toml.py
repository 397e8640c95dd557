"""Writing a :class:`~impact_env.transport.scenario.Scenario` back as a scenario file (the inverse of loading).

    text = scenario_to_toml(load_scenario("corridor"))
    assert scenario_from_toml(text, source="corridor") == load_scenario("corridor")

The task generator (:mod:`impact_env.transport.generate`) writes every task through this, so a generated
task is an ordinary scenario file that any tool reads. The writer knows the format's few shapes (strings,
floats, integers, pairs, boxes, inline tables, arrays of tables) and nothing more: no TOML library is
needed. Floats are written with ``repr`` (the shortest text that reads back to the same float), so
loading the text gives a scenario equal to the one written (given the same ``source``, which equality
also compares). Optional fields are written only when they
differ from the loader's default, so the files stay as short as hand-written ones.
"""

from __future__ import annotations

import json
import math

import numpy as np

from impact_env.errors import ScenarioError
from impact_env.geometry import ConvexPolygon
from impact_env.toml_fields import tomllib
from impact_env.transport.scenario import Body, Region, Scenario, scenario_from_dict

__all__ = ["scenario_from_toml", "scenario_to_toml"]


def _float(value: float) -> str:
    value = float(value)
    if not math.isfinite(value):
        raise ScenarioError(f"cannot write the non-finite number {value} to a scenario file")
    return repr(value)


def _string(text: str) -> str:
    return json.dumps(text, ensure_ascii=False)  # a JSON string is a TOML basic string


def _pair(values) -> str:
    return "[" + ", ".join(_float(v) for v in values) + "]"


def _is_box(polygon: ConvexPolygon) -> tuple[float, float, float, float] | None:
    """The box if ``polygon`` is exactly what ``ConvexPolygon.from_box`` builds (so ``box =`` reads back equal)."""
    xmin, xmax, ymin, ymax = polygon.bounds
    if xmin < xmax and ymin < ymax and polygon == ConvexPolygon.from_box(xmin, xmax, ymin, ymax):
        return xmin, xmax, ymin, ymax
    return None


def _region(table: str, region: Region) -> list[str]:
    lines = [f"[[{table}]]", f"name = {_string(region.name)}"]
    box = _is_box(region.polygon)
    if box is not None:
        lines.append(f"box = {_pair(box)}")
    else:
        lines.append("polygon = [" + ", ".join(_pair(v) for v in np.asarray(region.polygon.vertices)) + "]")
    return lines


def _body(table: str, body: Body) -> list[str]:
    lines = [f"[[{table}]]", f"name = {_string(body.name)}", f"mass_kg = {_float(body.mass_kg)}",
             f"radius_m = {_float(body.radius_m)}", f"inertia_kgm2 = {_float(body.inertia_kgm2)}",
             f"position_m = {_pair(body.position_m)}"]
    if tuple(body.velocity_mps) != (0.0, 0.0):
        lines.append(f"velocity_mps = {_pair(body.velocity_mps)}")
    if body.heading_rad != 0.0:
        lines.append(f"heading_rad = {_float(body.heading_rad)}")
    if body.angular_velocity_radps != 0.0:
        lines.append(f"angular_velocity_radps = {_float(body.angular_velocity_radps)}")
    for key in ("final_position_m", "final_velocity_mps", "velocity_bound_mps", "thrust_limit_N"):
        value = getattr(body, key)
        if value is not None:
            lines.append(f"{key} = {_pair(value)}")
    if body.torque_limit_Nm is not None:
        lines.append(f"torque_limit_Nm = {_float(body.torque_limit_Nm)}")
    return lines


def scenario_to_toml(scenario: Scenario, comment: str = "") -> str:
    """The scenario file of ``scenario``; ``comment`` (any lines) goes on top as ``#`` comments."""
    sc = scenario
    out = [f"# {line}".rstrip() for line in comment.splitlines()]
    out += [f"name = {_string(sc.name)}", f"description = {_string(sc.description)}",
            f"restitution = {_float(sc.restitution)}", f"tf_s = {_float(sc.tf_s)}",
            f"control_period_s = {_float(sc.control_period_s)}", f"substeps = {int(sc.substeps)}",
            f"task = {_string(sc.task)}", "", "[world]", f"box = {_pair(sc.world_box)}"]
    for table, regions in (("obstacles", sc.obstacles), ("regions", sc.regions)):
        for region in regions:
            out += ["", *_region(table, region)]
    for table, bodies in (("robots", sc.robots), ("objects", sc.objects)):
        for body in bodies:
            out += ["", *_body(table, body)]
    planner = []
    if sc.bezier_segments:
        planner.append("bezier_segments = { " + ", ".join(f"{_string(k)} = {int(v)}"
                                                          for k, v in sc.bezier_segments.items()) + " }")
    for key, value in (("intervals", sc.planner_intervals), ("robot_degree", sc.planner_robot_degree),
                       ("copy_intervals", sc.planner_copy_intervals)):
        if value is not None:
            planner.append(f"{key} = {int(value)}")
    if planner:
        out += ["", "[planner]", *planner]
    if sc.final_boxes:
        out += ["", "[final_box]"]
        out += [f"{_string(b.object)} = {{ position_m = {_pair(b.position_m)}, "
                f"velocity_mps = {_pair(b.velocity_mps)} }}" for b in sc.final_boxes]
    return "\n".join(out) + "\n"


def scenario_from_toml(text: str, source: str = "<toml>") -> Scenario:
    """Load a scenario from TOML text (as :func:`~impact_env.transport.scenario.load_scenario` loads a file)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    return scenario_from_dict(data, source=source)
