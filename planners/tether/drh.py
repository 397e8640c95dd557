"""The thesis's automaton in dReach's input language (``.drh``), for users who have dReach (dReal3).

A ``.drh`` file declares the variables with their ranges, then one block per mode (invariant, flow, jumps),
and the initial and the goal condition. Modes are numbered from 1: ``1`` is the initial mode, ``2`` the final
one, then the region modes in the automaton's order; each flow is Eq. 5 and every jump keeps ``(x, y)``.
dReach itself is not needed to write or check a file: :func:`parse_drh` reads it back and the tests check
every export against it. The full automaton is large (every ordered pair of a region's modes is a jump):
:func:`export_drh` refuses more than ``max_jumps`` jumps unless told otherwise, and :func:`subproblem_drh`
writes one divide-and-conquer sub-problem (Sec. 4.4), which is what the thesis ran. The grammar:
``docs/planner_design.md#drh-export``.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from planners.errors import PlannerError
from planners.tether.automaton import HalfPlane, HybridAutomaton, Mode


def _num(v: float) -> str:
    if not math.isfinite(v):
        raise PlannerError(f"cannot write the non-finite number {v} to a .drh file")
    s = f"{v:.12g}"
    return s if not s.startswith("-") else f"(0 - {s[1:]})"


def _atom(a: float, b: float, c: float) -> str:
    """``a x + b y <= c`` as a .drh comparison."""
    terms = []
    if abs(a) > 1e-15:
        terms.append(f"{_num(a)} * x")
    if abs(b) > 1e-15:
        terms.append(f"{_num(b)} * y")
    lhs = " + ".join(terms) if terms else "0"
    return f"({lhs} <= {_num(c)})"


def _conj(rows: tuple[HalfPlane, ...] | list[HalfPlane]) -> str:
    atoms = [_atom(*r) for r in rows]
    if not atoms:
        return "(and (x = x) (y = y))"
    return atoms[0] if len(atoms) == 1 else f"(and {' '.join(atoms)})"


def _flow(mode: Mode, ha: HybridAutomaton) -> tuple[str, str]:
    """Eq. 5: ``w`` times the sum over the mode's anchors of the unit vector toward each."""
    if not mode.anchors:
        return "0", "0"
    w = _num(ha.pull_speed_mps)
    fx, fy = [], []
    for a in mode.anchors:
        ax, ay = (_num(float(v)) for v in ha.anchor_positions[a])
        norm = f"sqrt(({ax} - x)^2 + ({ay} - y)^2)"
        fx.append(f"({ax} - x) / {norm}")
        fy.append(f"({ay} - y) / {norm}")
    return f"{w} * ({' + '.join(fx)})", f"{w} * ({' + '.join(fy)})"


def automaton_drh(ha: HybridAutomaton, bounds: tuple[float, float, float, float], horizon_s: float,
                  max_jumps: int | None = 20000) -> str:
    """The automaton as .drh text; ``bounds`` (xmin, xmax, ymin, ymax) are the variables' ranges."""
    if max_jumps is not None and ha.n_jumps > max_jumps:
        raise PlannerError(f"the automaton has {ha.n_jumps} jumps (more than max_jumps = {max_jumps}); export a "
                           "divide-and-conquer sub-problem (subproblem_drh), use k = 1, or pass max_jumps=None")
    number = {ha.initial: 1, ha.final: 2}
    for m in ha.modes:
        if m.name not in number:
            number[m.name] = len(number) + 1
    by_source: dict[str, list[str]] = {m.name: [] for m in ha.modes}
    for j in ha.jumps():
        guard = _conj(j.guard) if j.guard else _conj(ha.mode(j.source).invariant)
        by_source[j.source].append(f"        {guard} ==> @{number[j.target]} (and (x' = x) (y' = y));")
    x0, x1, y0, y1 = bounds
    lines = [f"[{_num(x0)}, {_num(x1)}] x;", f"[{_num(y0)}, {_num(y1)}] y;", f"[0, {_num(horizon_s)}] time;", ""]
    for m in sorted(ha.modes, key=lambda q: number[q.name]):
        fx, fy = _flow(m, ha)
        lines += [f"{{ mode {number[m.name]};", "  invt:"]
        lines += [f"        {_atom(*r)};" for r in m.invariant]
        lines += ["  flow:", f"        d/dt[x] = {fx};", f"        d/dt[y] = {fy};", "  jump:"]
        lines += by_source[m.name]
        lines += ["}", ""]
    init = ha.mode(ha.initial)
    final = ha.mode(ha.final)
    lines += ["init:", f"@1 {_conj(init.invariant)};", "", "goal:", f"@2 {_conj(final.invariant)};", ""]
    return "\n".join(lines)


def export_drh(ha: HybridAutomaton, path: str | Path, bounds: tuple[float, float, float, float],
               horizon_s: float, max_jumps: int | None = 20000) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(automaton_drh(ha, bounds, horizon_s, max_jumps))
    return path


def subproblem_drh(ha: HybridAutomaton, region: int, start: tuple[float, float], target: list[HalfPlane],
                   bounds: tuple[float, float, float, float], horizon_s: float) -> str:
    """One sub-problem of Sec. 4.4: the modes of ``region`` only, from ``start`` into the ``target`` rows (the
    overlap with the next region, or the goal box in the last sub-problem)."""
    modes = [m for m in ha.modes if m.region == region]
    if not modes:
        raise PlannerError(f"region {region} has no modes")
    sx, sy = start
    init = Mode("init", None, (), ((-1.0, 0.0, -sx), (1.0, 0.0, sx), (0.0, -1.0, -sy), (0.0, 1.0, sy)))
    final = Mode("final", None, (), tuple(target))
    names = [m.name for m in modes]
    sub = HybridAutomaton(station=ha.station, modes=[init, final, *modes],
                          jump_groups=[(names, names, ()), (["init"], names, ()), (names, ["final"], tuple(target))],
                          initial="init", final="final", start_m=(sx, sy), goal_box=ha.goal_box,
                          anchor_positions=ha.anchor_positions, pull_speed_mps=ha.pull_speed_mps, k=ha.k)
    return automaton_drh(sub, bounds, horizon_s, max_jumps=None)


# ------------------------------------------------------------------------------------------ grammar
_TOKEN = re.compile(r"\s*(?:(\d+\.?\d*(?:[eE][-+]?\d+)?)|(d/dt)|([A-Za-z_][A-Za-z_0-9]*'?)"
                    r"|(==>|<=|>=|[-+*/^()\[\];:,=<>@{}]))")


def _tokens(text: str) -> list[str]:
    out, pos = [], 0
    text = text.rstrip()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            raise PlannerError(f".drh syntax error at character {pos}: {text[pos:pos + 30]!r}")
        out.append(next(g for g in m.groups() if g is not None))
        pos = m.end()
    return out


class _Parser:
    """Recursive descent over the .drh subset described in the module docstring."""

    def __init__(self, text: str) -> None:
        self.t = _tokens(text)
        self.i = 0

    def peek(self) -> str | None:
        return self.t[self.i] if self.i < len(self.t) else None

    def eat(self, tok: str | None = None) -> str:
        got = self.peek()
        if got is None or (tok is not None and got != tok):
            raise PlannerError(f".drh syntax error at token {self.i}: expected {tok!r}, got {got!r}")
        self.i += 1
        return got

    def number(self) -> float:
        if self.peek() == "(":  # (0 - 5)
            self.eat("(")
            self.eat("0")
            self.eat("-")
            v = -self.number()
            self.eat(")")
            return v
        return float(self.eat())

    def expr(self, variables: set[str]) -> None:
        self.term(variables)
        while self.peek() in ("+", "-"):
            self.eat()
            self.term(variables)

    def term(self, variables: set[str]) -> None:
        self.factor(variables)
        while self.peek() in ("*", "/"):
            self.eat()
            self.factor(variables)

    def factor(self, variables: set[str]) -> None:
        self.base(variables)
        if self.peek() == "^":
            self.eat("^")
            self.base(variables)

    def base(self, variables: set[str]) -> None:
        tok = self.peek()
        if tok == "(":
            self.eat("(")
            self.expr(variables)
            self.eat(")")
        elif tok == "sqrt":
            self.eat("sqrt")
            self.eat("(")
            self.expr(variables)
            self.eat(")")
        elif tok is not None and re.fullmatch(r"\d+\.?\d*(?:[eE][-+]?\d+)?", tok):
            self.eat()
        elif tok in variables:
            self.eat()
        else:
            raise PlannerError(f".drh syntax error at token {self.i}: unexpected {tok!r} in an expression")

    def formula(self, variables: set[str]) -> None:
        self.eat("(")
        if self.peek() in ("and", "or"):
            self.eat()
            self.formula(variables)
            while self.peek() == "(":
                self.formula(variables)
        else:
            self.expr(variables)
            if self.peek() not in ("<=", ">=", "=", "<", ">"):
                raise PlannerError(f".drh syntax error at token {self.i}: expected a comparison, got {self.peek()!r}")
            self.eat()
            self.expr(variables)
        self.eat(")")

    def parse(self) -> dict:
        variables: list[str] = []
        while self.peek() == "[":
            self.eat("[")
            self.number()
            self.eat(",")
            self.number()
            self.eat("]")
            variables.append(self.eat())
            self.eat(";")
        if "time" not in variables:
            raise PlannerError(".drh: the variable 'time' is not declared")
        state = set(variables) - {"time"}
        primed = state | {v + "'" for v in state}
        modes: dict[int, dict] = {}
        while self.peek() == "{":
            self.eat("{")
            self.eat("mode")
            number = int(self.number())
            self.eat(";")
            self.eat("invt")
            self.eat(":")
            invariants = 0
            while self.peek() == "(":
                self.formula(state)
                self.eat(";")
                invariants += 1
            self.eat("flow")
            self.eat(":")
            flows = set()
            while self.peek() == "d/dt":
                self.eat("d/dt")
                self.eat("[")
                var = self.eat()
                self.eat("]")
                self.eat("=")
                self.expr(state)
                self.eat(";")
                flows.add(var)
            if flows != state:
                raise PlannerError(f".drh: mode {number} has flows for {sorted(flows)}, not for {sorted(state)}")
            self.eat("jump")
            self.eat(":")
            targets = []
            while self.peek() == "(":
                self.formula(state)
                self.eat("==>")
                self.eat("@")
                targets.append(int(self.number()))
                self.formula(primed)
                self.eat(";")
            self.eat("}")
            if number in modes:
                raise PlannerError(f".drh: mode {number} is defined twice")
            modes[number] = {"invariants": invariants, "jumps": targets}
        out: dict[str, Any] = {"variables": variables, "modes": modes}
        for key in ("init", "goal"):
            self.eat(key)
            self.eat(":")
            self.eat("@")
            out[key] = int(self.number())
            self.formula(state)
            self.eat(";")
        if self.peek() is not None:
            raise PlannerError(f".drh: unexpected {self.peek()!r} after the goal")
        for number, mode in modes.items():
            for t in mode["jumps"]:
                if t not in modes:
                    raise PlannerError(f".drh: mode {number} jumps to undefined mode {t}")
        for key in ("init", "goal"):
            if out[key] not in modes:
                raise PlannerError(f".drh: {key} names undefined mode {out[key]}")
        return out


def parse_drh(text: str) -> dict:
    """Check ``text`` against the grammar of the module docstring; returns the variables, and per mode number
    its invariant count and jump targets, and the init and goal modes. Raises PlannerError on a syntax error."""
    return _Parser(text).parse()
