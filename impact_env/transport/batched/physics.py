"""The impact world's substep for a whole batch: chipmunk's scheme as tensor ops (the reference kernel).

Layout is batch-minor. The contact-dependent state of N envs is one ``[F, N]`` tensor of rows
(:class:`RowLayout`): x, y, vx, vy and the two bias-velocity components of every body, then one on-flag (0 or
1) per body pair and per (static shape, body). Headings and yaw rates are separate ``[B, N]`` tensors: a
frictionless contact through the centres creates no spin, so they follow from the torque alone, and
:func:`headings` advances them over a whole control period at once.

A substep does what ``cpSpaceStep`` does for these bodies (chipmunk 7, which pymunk 7 wraps), in its order:

1. positions move with the velocities of the end of the previous substep plus the bias velocity that the
   previous substep's contacts left (chipmunk's position correction; then reset to 0);
2. contacts are detected at the new positions: disc-disc when the centre distance is < r_a + r_b,
   disc-wall and disc-obstacle when the centre is <= r from the shape (closest point of the convex shape,
   or the normal of the nearest face when the centre is inside it). Each contact's target is set from the
   velocities before this substep's thrust: normal relative velocity after = -e times before (Newton's
   law of restitution, the paper's Eq. 5-7 for frictionless discs), and a bias velocity that removes
   ``bias_coef`` of the overlap beyond the 0.1 mm slop;
3. velocities take the thrust (rotated by the heading at the start of the substep): v += (F / m) dt;
4. impulses along each contact normal, accumulated and clamped at >= 0 (a contact pushes, never pulls), in
   the fixed order of :mod:`impact_env.transport.batched.scene`, ``iterations`` passes (chipmunk: 10);
5. a robot-object contact that ended in this substep gives the object its post-impact velocity error.

An env in which no body has two contacts at once meets every target exactly in pass 1, and later passes
add exactly 0 to it (they are masked per env), so an isolated impact follows the law whatever the other
envs do. Where a body has several contacts at once the passes are Gauss-Seidel iterations as chipmunk's, but
in this fixed order, where chipmunk visits contacts in the order of a hash set keyed by C addresses; chipmunk
also warm-starts a contact that lasts several substeps with its previous impulse. Both change only how the
iterations approach the simultaneous solution. Chipmunk's spin from rounding (r x n of a contact through the
centre, ~1e-17 rad/s) is exactly 0 here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypedDict

import torch

from impact_env.transport.batched.scene import BoxShape, PolygonShape, Scene, pair_arrays

_INF = float("inf")
WALL_NORMALS = ((0.0, -1.0), (0.0, 1.0), (-1.0, 0.0), (1.0, 0.0))  # from a body into the wall: bottom, top, left, right
WALL_AXIS_SIGN = ((1, -1.0), (1, 1.0), (0, -1.0), (0, 1.0))


class TensorKwargs(TypedDict):
    """The ``device`` and ``dtype`` keywords every tensor of a batch is made with (``torch.zeros(n, **opts)``)."""

    device: torch.device
    dtype: torch.dtype


@dataclass(frozen=True)
class RowLayout:
    """Where each quantity sits in the ``[F, N]`` substep state."""

    n_bodies: int
    n_pairs: int
    n_static: int

    @property
    def pair_on(self) -> slice:
        return slice(6 * self.n_bodies, 6 * self.n_bodies + self.n_pairs)

    @property
    def static_on(self) -> slice:
        return slice(self.pair_on.stop, self.pair_on.stop + self.n_static * self.n_bodies)

    @property
    def n_rows(self) -> int:
        return self.static_on.stop

    @property
    def n_contacts(self) -> int:
        """Pairs, then (static shape, body) in static-major order."""
        return self.n_pairs + self.n_static * self.n_bodies

    def field(self, k: int) -> slice:
        """Rows of field k over the bodies: 0 x, 1 y, 2 vx, 3 vy, 4 bias vx, 5 bias vy."""
        return slice(k * self.n_bodies, (k + 1) * self.n_bodies)


def headings(ang: torch.Tensor, omg: torch.Tensor, dtorque: torch.Tensor, substeps: int,
             dt_s: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Headings (rad) at the start of each substep [substeps, B, N], and the heading and yaw rate after.

    chipmunk's order: heading += omega dt with the old omega, then omega += (tau / I) dt (``dtorque`` [B, N]
    is that increment, 0 for objects).
    """
    starts = []
    for _ in range(substeps):
        starts.append(ang)
        ang = ang + omg * dt_s
        omg = omg + dtorque
    return torch.stack(starts), ang, omg


def world_forces(start_headings: torch.Tensor, fx: torch.Tensor, fy: torch.Tensor) -> torch.Tensor:
    """Body-frame forces [R, N] rotated by the robots' headings [substeps, R, N]: [2, substeps, R, N] (N).

    (x, y) is the leading axis so that each part is computed contiguously over the envs (a vectorised loop).
    """
    c, s = torch.cos(start_headings), torch.sin(start_headings)
    return torch.stack((c * fx - s * fy, s * fx + c * fy))


class ReferenceKernel:
    """The substep of every env of a batch, vectorised over bodies and contacts (eager torch, any device).

    ``eager_skips``: contact groups with no contact in any env of the batch (and passes after the first
    where no env has a body with two contacts) are skipped; a skipped group would add exactly 0 to every
    velocity, so results do not depend on the batch.
    """

    def __init__(self, scene: Scene, device: torch.device, dtype: torch.dtype, iterations: int = 10) -> None:
        self.scene = scene
        self.iterations = iterations
        self.layout = RowLayout(scene.n_bodies, len(scene.pairs), scene.n_static)
        B = scene.n_bodies
        opts = TensorKwargs(device=device, dtype=dtype)
        self.inv_mass = torch.tensor(scene.inv_mass, **opts).reshape(B, 1)
        self.static_nmass = 1.0 / self.inv_mass  # chipmunk's 1 / (1/m + 0) against a static shape
        self.radius = torch.tensor(scene.radius_m, **opts).reshape(B, 1)
        i, j = pair_arrays(scene)
        self.pair_i = torch.tensor(i, device=device)
        self.pair_j = torch.tensor(j, device=device)
        rsum = [scene.radius_m[a] + scene.radius_m[b] for a, b in scene.pairs]
        self.pair_rsum = torch.tensor(rsum, **opts).reshape(-1, 1)
        self.pair_rsum2 = torch.tensor([r * r for r in rsum], **opts).reshape(-1, 1)
        self.incidence = torch.zeros(B, len(scene.pairs), **opts)  # body b takes part in pair p
        for p, (a, b) in enumerate(scene.pairs):
            self.incidence[a, p] = self.incidence[b, p] = 1.0
        self.wall_normals = torch.tensor(WALL_NORMALS, **opts).reshape(4, 2, 1, 1)
        xmin, xmax, ymin, ymax = scene.world_box
        self.wall_axis = torch.tensor([1, 1, 0, 0], device=device)
        self.wall_sign = torch.tensor([1.0, -1.0, 1.0, -1.0], **opts).reshape(4, 1, 1)
        self.wall_offset = torch.tensor([-ymin, ymax, -xmin, xmax], **opts).reshape(4, 1, 1)
        boxes = [o for o in scene.obstacles if isinstance(o, BoxShape)]
        self.box_index = torch.tensor([k for k, o in enumerate(scene.obstacles) if isinstance(o, BoxShape)],
                                      dtype=torch.int64)
        self.box_lo = torch.tensor([[o.x0, o.y0] for o in boxes], **opts).reshape(-1, 2, 1, 1)
        self.box_hi = torch.tensor([[o.x1, o.y1] for o in boxes], **opts).reshape(-1, 2, 1, 1)
        self.eager_skips = True

    # --------------------------------------------------------------------------------------- detection
    def _bias(self, gap: torch.Tensor) -> torch.Tensor:
        """chipmunk's target bias velocity (m/s) of a contact with signed gap ``gap`` (m, < 0: overlap)."""
        sc = self.scene
        return (-sc.bias_coef) * torch.clamp(gap + sc.slop_m, max=0.0) / sc.dt_s

    def _pairs(self, pos: torch.Tensor, vel: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Normals [2, P, N] (from body i to j), targets [2(channel), P, N] and on-flags [P, N] of body pairs."""
        d = pos.index_select(1, self.pair_j) - pos.index_select(1, self.pair_i)
        d2 = d[0] * d[0] + d[1] * d[1]
        on = d2 < self.pair_rsum2
        dist = torch.sqrt(d2)
        ok = dist > 0.0
        inv = torch.where(ok, 1.0 / dist, 0.0)  # chipmunk: n = delta * (1 / |delta|), (1, 0) if coincident
        n = torch.stack((torch.where(ok, d[0] * inv, 1.0), d[1] * inv))
        rel = vel.index_select(1, self.pair_j) - vel.index_select(1, self.pair_i)
        vrn = rel[0] * n[0] + rel[1] * n[1]
        tgt = torch.stack((-(vrn * self.scene.restitution), self._bias(dist - self.pair_rsum)))
        return n, torch.where(on, tgt, -_INF), on

    def _obstacles(self, pos: torch.Tensor, vel: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Normals [O, 2, B, N], centre-to-shape distances [O, B, N] (< 0 inside) and normal relative
        velocities [O, B, N] of the obstacles, in scenario order: boxes all at once (a clamp), polygons one by one."""
        sc = self.scene
        if self.box_index.numel() == len(sc.obstacles):  # only boxes (every shipped scenario)
            d = torch.minimum(torch.maximum(pos, self.box_lo), self.box_hi) - pos  # [O, 2, B, N]
            dx, dy = d[:, 0], d[:, 1]
            d2 = dx * dx + dy * dy
        else:
            d = torch.minimum(torch.maximum(pos, self.box_lo), self.box_hi) - pos  # [boxes, 2, B, N]
            box_row = {k: i for i, k in enumerate(self.box_index.tolist())}
            parts: list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]] = []
            for k, o in enumerate(sc.obstacles):
                if isinstance(o, PolygonShape):
                    parts.append(polygon_closest(o, pos[0], pos[1]))
                else:
                    i = box_row[k]
                    parts.append((d[i, 0], d[i, 1], d[i, 0] * d[i, 0] + d[i, 1] * d[i, 1]))
            dx, dy, d2 = (torch.stack([p[m] for p in parts]) for m in range(3))
        outside = d2 > 0.0
        dist = torch.sqrt(d2)
        inv = torch.where(outside, 1.0 / dist, 0.0)
        nx, ny = dx * inv, dy * inv
        if not (self.eager_skips and bool(outside.all())):
            inside = [inside_normal(o, pos[0], pos[1]) for o in sc.obstacles]
            nx = torch.where(outside, nx, torch.stack([i[0] for i in inside]))
            ny = torch.where(outside, ny, torch.stack([i[1] for i in inside]))
            dist = torch.where(outside, dist, -torch.stack([i[2] for i in inside]))
        return torch.stack((nx, ny), dim=1), dist, -(vel[0] * nx + vel[1] * ny)

    def detect(self, pos: torch.Tensor, vel: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Contacts at positions ``pos`` [2, B, N] with targets from the pre-thrust velocities ``vel``:
        (pair normals, pair targets, pair on, static normals [S, 2, B, N], static targets [S, 2, B, N],
        static on [S, B, N])."""
        N = pos.shape[2]
        if self.scene.pairs:
            pair_n, pair_tgt, pair_on = self._pairs(pos, vel)
        else:
            pair_n, pair_tgt = pos.new_zeros(2, 0, N), pos.new_zeros(2, 0, N)
            pair_on = torch.zeros(0, N, dtype=torch.bool, device=pos.device)
        # walls: distance from the centre to the face and normal relative velocity, all four at once:
        # y - ymin, ymax - y, x - xmin, xmax - x (exactly: x * -1 + c is c - x) and vy, -vy, vx, -vx
        dist = pos.index_select(0, self.wall_axis) * self.wall_sign + self.wall_offset  # [4, B, N]
        vn = vel.index_select(0, self.wall_axis) * self.wall_sign
        normals = self.wall_normals.expand(4, 2, *pos.shape[1:])
        if self.scene.obstacles:
            obs_n, obs_dist, obs_vn = self._obstacles(pos, vel)
            dist, vn, normals = torch.cat((dist, obs_dist)), torch.cat((vn, obs_vn)), torch.cat((normals, obs_n))
        on = dist <= self.radius
        tgt = torch.stack((-(vn * self.scene.restitution), self._bias(dist - self.radius)), dim=1)
        return pair_n, pair_tgt, pair_on, normals, torch.where(on.unsqueeze(1), tgt, -_INF), on

    # ---------------------------------------------------------------------------------------- impulses
    def solve(self, v: torch.Tensor, contacts: tuple[torch.Tensor, ...]) -> torch.Tensor:
        """Sequential impulses on ``v`` = [2(channel: velocity, bias velocity), 2(xy), B, N]; returns it."""
        sc = self.scene
        pair_n, pair_tgt, pair_on, static_n, static_tgt, static_on = contacts
        n_pairs = len(sc.pairs)
        counts = static_on.sum(0, dtype=v.dtype)
        if n_pairs:
            counts = counts + self.incidence @ pair_on.to(v.dtype)
        multi = (counts >= 2.0).any(0)  # [N]: a body of the env has two contacts at once
        group_on = None
        if self.eager_skips:
            group_on = torch.cat((pair_on.any(1), static_on.flatten(1).any(1), multi.any().reshape(1))).tolist()
        pair_acc = [v.new_zeros(2, v.shape[-1]) for _ in range(n_pairs)]
        static_acc = [v.new_zeros(2, v.shape[2], v.shape[3]) for _ in range(sc.n_static)]
        minv = sc.inv_mass
        for it in range(self.iterations):
            if it and group_on is not None and not group_on[-1]:
                break
            mask = multi if it else None
            for p, (a, b) in enumerate(sc.pairs):
                if group_on is not None and not group_on[p]:
                    continue
                n = pair_n[:, p]
                rel = v[:, :, b] - v[:, :, a]
                vn = rel[:, 0] * n[0] + rel[:, 1] * n[1]
                jn = (pair_tgt[:, p] - vn) * (1.0 / (minv[a] + minv[b]))
                if mask is not None:
                    jn = torch.where(mask, jn, 0.0)
                new = torch.clamp(pair_acc[p] + jn, min=0.0)
                dj = new - pair_acc[p]
                pair_acc[p] = new
                imp = dj.unsqueeze(1) * n
                v[:, :, a] = v[:, :, a] - imp * minv[a]
                v[:, :, b] = v[:, :, b] + imp * minv[b]
            for s in range(sc.n_static):
                if group_on is not None and not group_on[n_pairs + s]:
                    continue
                if s < 4:  # a wall's normal is an axis: one component changes (the others' terms are +-0)
                    axis, sign = WALL_AXIS_SIGN[s]
                    comp = v[:, axis]
                    vn = comp if sign < 0 else -comp
                else:
                    nx, ny = static_n[s, 0], static_n[s, 1]
                    vn = -(v[:, 0] * nx + v[:, 1] * ny)
                jn = (static_tgt[s] - vn) * self.static_nmass
                if mask is not None:
                    jn = torch.where(mask, jn, 0.0)
                new = torch.clamp(static_acc[s] + jn, min=0.0)
                dj = new - static_acc[s]
                static_acc[s] = new
                if s < 4:
                    v[:, axis] = comp + dj * self.inv_mass if sign < 0 else comp - dj * self.inv_mass
                else:
                    v[:, 0] = v[:, 0] - (dj * nx) * self.inv_mass
                    v[:, 1] = v[:, 1] - (dj * ny) * self.inv_mass
        return v

    # ------------------------------------------------------------------------------------- free flight
    def clear_of_contacts(self, rows: torch.Tensor, force_max: torch.Tensor, period_s: float) -> bool:
        """True if no contact is open and none can start within ``period_s`` in any env of the batch.

        Bound: a body moves at most (|v| + |F|/m T) T in a period T (``force_max`` [R, N]: |F| of each robot,
        N), and every gap (centre distance minus radii, or centre-to-shape distance minus radius) at the start
        exceeds the sum of the moves that could close it. Then every substep is free flight, bit for bit the
        same as the full substep (whose contact passes would all add exactly 0).
        """
        sc, lay = self.scene, self.layout
        B, N = sc.n_bodies, rows.shape[1]
        if bool((rows[lay.pair_on.start:lay.static_on.stop] > 0.5).any()):
            return False
        pos = rows[: 2 * B].reshape(2, B, N)
        vel = rows[2 * B: 4 * B].reshape(2, B, N)
        accel = torch.cat((force_max * self.inv_mass[: sc.n_robots], vel.new_zeros(B - sc.n_robots, N)))
        move = (torch.sqrt(vel[0] * vel[0] + vel[1] * vel[1]) + accel * period_s) * period_s * 1.01 + 1e-6
        xmin, xmax, ymin, ymax = sc.world_box
        x, y = pos[0], pos[1]
        wall = torch.minimum(torch.minimum(x - xmin, xmax - x), torch.minimum(y - ymin, ymax - y)) - self.radius
        ok = (wall > move).all()
        for shape in sc.obstacles:
            if isinstance(shape, BoxShape):
                dx = torch.clamp(x, shape.x0, shape.x1) - x
                dy = torch.clamp(y, shape.y0, shape.y1) - y
                d2 = dx * dx + dy * dy
            else:
                d2 = polygon_closest(shape, x, y)[2]
            ok = ok & (torch.sqrt(d2) - self.radius > move).all()
        if sc.pairs:
            d = pos.index_select(1, self.pair_j) - pos.index_select(1, self.pair_i)
            gap = torch.sqrt(d[0] * d[0] + d[1] * d[1]) - self.pair_rsum
            ok = ok & (gap > move.index_select(0, self.pair_i) + move.index_select(0, self.pair_j)).all()
        return bool(ok)

    def free_flight(self, rows: torch.Tensor, force: torch.Tensor) -> torch.Tensor:
        """All substeps of a period without contacts (``force`` [2, substeps, R, N]); see clear_of_contacts."""
        sc = self.scene
        B, R, N = sc.n_bodies, sc.n_robots, rows.shape[1]
        pos = rows[: 2 * B].reshape(2, B, N)
        vel = rows[2 * B: 4 * B].reshape(2, B, N)
        vbias = rows[4 * B: 6 * B].reshape(2, B, N)
        robots = vel[:, :R]
        objects = vel[:, R:]
        minv = self.inv_mass[:R]
        pos = pos + (vel + vbias) * sc.dt_s  # the first substep moves with the last bias velocity (0 here)
        pos_r, pos_o = pos[:, :R], pos[:, R:]
        for k in range(sc.substeps):
            if k:
                pos_r = pos_r + robots * sc.dt_s
                pos_o = pos_o + objects * sc.dt_s
            robots = robots + (force[:, k] * minv) * sc.dt_s
        out = rows.clone()
        out[: 2 * B] = torch.cat((pos_r, pos_o), dim=1).reshape(2 * B, N)
        out[2 * B: 4 * B] = torch.cat((robots, objects), dim=1).reshape(2 * B, N)
        out[4 * B: 6 * B] = 0.0
        return out

    # ------------------------------------------------------------------------------------------ substep
    def substep(self, rows: torch.Tensor, ended: torch.Tensor, force: torch.Tensor,
                impact_noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """One substep of every env.

        Args:
            rows: [F, N] substep state (:class:`RowLayout`).
            ended: [C, N] count of contacts that ended so far this period (pairs, then static x body).
            force: [2, R, N] the robots' world-frame thrust (N) in this substep.
            impact_noise: [n_robot_object_pairs, 2, N] velocity error (m/s) of an object whose contact with
                that robot ends in this substep, or None.
        Returns the new rows and counts.
        """
        sc, lay = self.scene, self.layout
        B, N = sc.n_bodies, rows.shape[1]
        pos = rows[: 2 * B].reshape(2, B, N)
        vel = rows[2 * B: 4 * B].reshape(2, B, N)
        vbias = rows[4 * B: 6 * B].reshape(2, B, N)
        pos = pos + (vel + vbias) * sc.dt_s
        contacts = self.detect(pos, vel)
        thrust = torch.cat((force * self.inv_mass[: sc.n_robots], vel.new_zeros(2, B - sc.n_robots, N)), dim=1)
        vel = vel + thrust * sc.dt_s
        v = self.solve(torch.stack((vel, torch.zeros_like(vel))), contacts)
        vel, vbias = v[0], v[1]
        pair_on, static_on = contacts[2], contacts[5]
        sep_pairs = (rows[lay.pair_on] > 0.5) & ~pair_on
        sep_static = (rows[lay.static_on] > 0.5) & ~static_on.flatten(0, 1)
        if impact_noise is not None and sc.robot_object_pairs:
            for q, (p, obj) in enumerate(sc.robot_object_pairs):
                vel[:, obj] = vel[:, obj] + torch.where(sep_pairs[p], impact_noise[q], 0.0)
        out = torch.cat((pos.reshape(2 * B, N), vel.reshape(2 * B, N), vbias.reshape(2 * B, N),
                         pair_on.to(rows.dtype), static_on.flatten(0, 1).to(rows.dtype)))
        return out, ended + torch.cat((sep_pairs, sep_static)).to(ended.dtype)


def polygon_closest(shape: PolygonShape, x: torch.Tensor,
                    y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(dx, dy, d2) from centres (x, y) to the closest boundary point of a convex polygon; d2 = 0 inside."""
    verts = shape.vertices

    def edge_closest(k: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        (vx, vy), (wx, wy) = verts[k], verts[(k + 1) % len(verts)]
        ex, ey = wx - vx, wy - vy
        t = torch.clamp(((x - vx) * ex + (y - vy) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        dx, dy = (vx + t * ex) - x, (vy + t * ey) - y
        return dx, dy, dx * dx + dy * dy

    bx, by, bd2 = edge_closest(0)
    for k in range(1, len(verts)):
        dx, dy, d2 = edge_closest(k)
        closer = d2 < bd2
        bx, by, bd2 = torch.where(closer, dx, bx), torch.where(closer, dy, by), torch.where(closer, d2, bd2)
    edges = list(zip(shape.normals, shape.offsets))
    (nx, ny), off = edges[0]
    inside = nx * x + ny * y - off <= 0.0
    for (nx, ny), off in edges[1:]:
        inside = inside & (nx * x + ny * y - off <= 0.0)
    return bx, by, torch.where(inside, 0.0, bd2)


def inside_normal(shape: BoxShape | PolygonShape, x: torch.Tensor,
                  y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """For centres inside the shape: the normal into the shape through its nearest face, and the depth (m)."""
    faces: list[tuple[tuple[float, float], float]]
    if isinstance(shape, BoxShape):
        faces = [((-1.0, 0.0), -shape.x0), ((1.0, 0.0), shape.x1), ((0.0, -1.0), -shape.y0), ((0.0, 1.0), shape.y1)]
    else:
        faces = list(zip(shape.normals, shape.offsets))
    (fx, fy), off = faces[0]
    depth = off - (fx * x + fy * y)  # >= 0 inside
    nx, ny = torch.full_like(x, -fx), torch.full_like(x, -fy)
    for (fx, fy), off in faces[1:]:
        d = off - (fx * x + fy * y)
        nearer = d < depth
        depth = torch.where(nearer, d, depth)
        nx, ny = torch.where(nearer, -fx, nx), torch.where(nearer, -fy, ny)
    return nx, ny, depth
