"""One control period of the impact world for a whole batch: chipmunk's substep scheme as tensor ops.

Layout is batch-minor: every state tensor ends with the env axis (``[2, n_bodies, N]`` for positions and
velocities, ``[n_bodies, N]`` for headings), so each operation runs over contiguous envs.

A substep does what ``cpSpaceStep`` does for these bodies (chipmunk 7, which pymunk 7 wraps), in its order:

1. positions and headings move with the velocities of the end of the previous substep, plus the *bias
   velocity* the previous substep's contacts left (chipmunk's position correction, then reset to 0);
2. contacts are detected at the new positions: disc-disc when the centre distance is < r_a + r_b, disc-wall
   and disc-obstacle when the distance from the centre to the shape is <= r (closest point on the convex
   shape; the normal of the nearest face when the centre is inside it). Each contact's target is set from
   the velocities *before* this substep's thrust: normal relative velocity after = -e times before (Newton's
   restitution law, the paper's Eq. 5-7 for frictionless discs), and a bias velocity that removes
   ``bias_coef`` of the overlap beyond the 0.1 mm slop;
3. velocities take the thrust (rotated by the heading before step 1) and torque, semi-implicit Euler:
   v += (F / m) dt, omega += (tau / I) dt;
4. impulses along each contact normal, accumulated and clamped at >= 0 (a contact can push, never pull),
   in a fixed order (:mod:`impact_env.transport.batched.scene`), ``iterations`` passes (chipmunk's default
   is 10). A contact through the centres of frictionless discs creates no spin, so headings and yaw rates
   follow from the torque alone.
5. a robot-object contact that ended in this substep gives the object its post-impact velocity error.

For a body in at most one contact (nearly all impacts) pass 1 meets the target exactly and later passes are
skipped for that env, so the result is the law itself. Where one body is in several contacts at once, the
passes are Gauss-Seidel iterations over them as chipmunk's, but in this fixed order, while chipmunk visits
them in the order of a hash set keyed by C addresses, and chipmunk also warm-starts a contact that lasts
several substeps with its previous impulse; both only change how the iterations approach the simultaneous
solution, not the law of an isolated impact. Spin from rounding (chipmunk's r x n of a contact through the
centre, ~1e-17) is exactly 0 here.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from impact_env.transport.batched.scene import BoxShape, PolygonShape, Scene, pair_arrays

_INF = float("inf")


class PhysicsState(NamedTuple):
    """The bodies of N envs (SI units). Body axis in scenario order (robots, then objects)."""

    pos: torch.Tensor  # [2, B, N] x, y (m)
    vel: torch.Tensor  # [2, B, N] (m/s)
    vbias: torch.Tensor  # [2, B, N] chipmunk's bias velocity, moved with in the next substep (m/s)
    ang: torch.Tensor  # [B, N] heading (rad)
    omg: torch.Tensor  # [B, N] yaw rate (rad/s)
    pair_on: torch.Tensor  # [P, N] bool: body pair in contact after the last substep
    static_on: torch.Tensor  # [S, B, N] bool: body touching a wall or obstacle after the last substep


class Contacts(NamedTuple):
    """One substep's contacts: normals (from body a to b, or from the body into the static shape), targets
    (per channel: 0 = velocity, 1 = bias velocity; -inf where there is no contact) and the on-flags."""

    pair_n: torch.Tensor  # [2, P, N]
    pair_tgt: torch.Tensor  # [2(channel), P, N]
    pair_on: torch.Tensor  # [P, N]
    static_n: torch.Tensor  # [S, 2, B, N] (walls: constant normals)
    static_tgt: torch.Tensor  # [S, 2(channel), B, N]
    static_on: torch.Tensor  # [S, B, N]


class PeriodKernel:
    """The physics of one control period for N envs of one scene, on one device and dtype.

    ``eager_skips``: in eager mode, contact groups with no contact in any env of the batch (and passes after
    the first where no body of any env has two contacts) are skipped. A skipped group would add exactly 0 to
    every velocity, so results do not depend on the batch; under torch.compile nothing is skipped (no
    data-dependent Python).
    """

    def __init__(self, scene: Scene, device: torch.device, dtype: torch.dtype, iterations: int = 10) -> None:
        self.scene = scene
        self.iterations = iterations
        self.dtype = dtype
        B, R = scene.n_bodies, scene.n_robots
        opts = {"device": device, "dtype": dtype}
        col = (B, 1)
        self.inv_mass = torch.tensor(scene.inv_mass, **opts).reshape(col)
        self.radius = torch.tensor(scene.radius_m, **opts).reshape(col)
        self.static_nmass = 1.0 / self.inv_mass  # chipmunk's 1 / (1/m + 0) for a body against a static shape
        self.inv_inertia_robot = torch.tensor(scene.inv_inertia[:R], **opts).reshape(R, 1)
        i, j = pair_arrays(scene)
        self.pair_i = torch.tensor(i, device=device)
        self.pair_j = torch.tensor(j, device=device)
        rsum = [scene.radius_m[a] + scene.radius_m[b] for a, b in scene.pairs]
        self.pair_rsum = torch.tensor(rsum, **opts).reshape(-1, 1)
        self.pair_rsum2 = torch.tensor([r * r for r in rsum], **opts).reshape(-1, 1)
        # contact incidence: body b takes part in pair p
        incidence = torch.zeros(B, len(scene.pairs), **opts)
        for p, (a, b) in enumerate(scene.pairs):
            incidence[a, p] = incidence[b, p] = 1.0
        self.incidence = incidence
        # constant wall normals (from the body into the wall): bottom, top, left, right
        self._wall_n = [(0.0, -1.0), (0.0, 1.0), (-1.0, 0.0), (1.0, 0.0)]
        self.eager_skips = True

    # --------------------------------------------------------------------------------------- detection
    def _pairs(self, pos: torch.Tensor, vel: torch.Tensor) -> tuple[torch.Tensor, ...]:
        sc = self.scene
        d = pos.index_select(1, self.pair_j) - pos.index_select(1, self.pair_i)  # [2, P, N]
        d2 = d[0] * d[0] + d[1] * d[1]
        on = d2 < self.pair_rsum2
        dist = torch.sqrt(d2)
        ok = dist > 0.0
        inv = torch.where(ok, 1.0 / dist, 0.0)  # chipmunk: n = delta * (1 / |delta|), (1, 0) if coincident
        n = torch.stack((torch.where(ok, d[0] * inv, 1.0), d[1] * inv))
        rel = vel.index_select(1, self.pair_j) - vel.index_select(1, self.pair_i)
        vrn = rel[0] * n[0] + rel[1] * n[1]
        tgt = torch.stack((-(vrn * sc.restitution), self._bias(dist - self.pair_rsum)))
        return n, torch.where(on, tgt, -_INF), on

    def _bias(self, gap: torch.Tensor) -> torch.Tensor:
        """chipmunk's target bias velocity of a contact whose signed gap (m) is ``gap`` (< 0: overlap)."""
        sc = self.scene
        return (-sc.bias_coef) * torch.clamp(gap + sc.slop_m, max=0.0) / sc.dt_s

    def _static_target(self, dist: torch.Tensor, vn: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(targets [2, B, N], on [B, N]) of a static contact: centre-to-shape distance, normal velocity."""
        on = dist <= self.radius
        tgt = torch.stack((-(vn * self.scene.restitution), self._bias(dist - self.radius)))
        return torch.where(on, tgt, -_INF), on

    def _walls(self, pos: torch.Tensor, vel: torch.Tensor) -> list[tuple[torch.Tensor, ...]]:
        xmin, xmax, ymin, ymax = self.scene.world_box
        x, y, vx, vy = pos[0], pos[1], vel[0], vel[1]
        out = []
        # (distance from the centre to the wall's face, normal relative velocity static - body along n)
        for dist, vn in ((y - ymin, vy), (ymax - y, -vy), (x - xmin, vx), (xmax - x, -vx)):
            tgt, on = self._static_target(dist, vn)
            out.append((tgt, on))
        return out

    def _obstacle(self, shape: BoxShape | PolygonShape, pos: torch.Tensor,
                  vel: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        x, y = pos[0], pos[1]
        if isinstance(shape, BoxShape):
            dx = torch.clamp(x, shape.x0, shape.x1) - x
            dy = torch.clamp(y, shape.y0, shape.y1) - y
            d2 = dx * dx + dy * dy
        else:
            dx, dy, d2 = self._polygon_closest(shape, x, y)
        outside = d2 > 0.0
        dist = torch.sqrt(d2)
        inv = torch.where(outside, 1.0 / dist, 0.0)
        nx, ny = dx * inv, dy * inv
        if not (self.eager_skips and not torch.compiler.is_compiling()) or not bool(outside.all()):
            in_nx, in_ny, depth = self._inside(shape, x, y)
            nx = torch.where(outside, nx, in_nx)
            ny = torch.where(outside, ny, in_ny)
            dist = torch.where(outside, dist, -depth)
        vn = -(vel[0] * nx + vel[1] * ny)
        tgt, on = self._static_target(dist, vn)
        return torch.stack((nx, ny)), tgt, on

    @staticmethod
    def _polygon_closest(shape: PolygonShape, x: torch.Tensor, y: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """(dx, dy, d2): from the centre to the closest point of the polygon's boundary."""
        best = None
        verts = shape.vertices
        for k, (vx, vy) in enumerate(verts):
            wx, wy = verts[(k + 1) % len(verts)]
            ex, ey = wx - vx, wy - vy
            t = torch.clamp(((x - vx) * ex + (y - vy) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
            dx = (vx + t * ex) - x
            dy = (vy + t * ey) - y
            d2 = dx * dx + dy * dy
            if best is None:
                best = (dx, dy, d2)
            else:
                closer = d2 < best[2]
                best = (torch.where(closer, dx, best[0]), torch.where(closer, dy, best[1]),
                        torch.where(closer, d2, best[2]))
        inside = None
        for (nx, ny), off in zip(shape.normals, shape.offsets):
            edge_in = nx * x + ny * y - off <= 0.0
            inside = edge_in if inside is None else inside & edge_in
        return best[0], best[1], torch.where(inside, 0.0, best[2])

    @staticmethod
    def _inside(shape: BoxShape | PolygonShape, x: torch.Tensor,
                y: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """For a centre inside the shape: the normal pointing into it through its nearest face, and the depth."""
        if isinstance(shape, BoxShape):
            faces = (((-1.0, 0.0), -shape.x0), ((1.0, 0.0), shape.x1), ((0.0, -1.0), -shape.y0),
                     ((0.0, 1.0), shape.y1))
        else:
            faces = tuple(zip(shape.normals, shape.offsets))
        depth = nx = ny = None
        for (fx, fy), off in faces:
            d = off - (fx * x + fy * y)  # >= 0 inside
            if depth is None:
                depth, nx, ny = d, torch.full_like(x, -fx), torch.full_like(x, -fy)
            else:
                nearer = d < depth
                depth = torch.where(nearer, d, depth)
                nx = torch.where(nearer, -fx, nx)
                ny = torch.where(nearer, -fy, ny)
        return nx, ny, depth

    def detect(self, pos: torch.Tensor, vel: torch.Tensor) -> Contacts:
        """Contacts at positions ``pos`` with targets from the pre-thrust velocities ``vel``."""
        B, N = pos.shape[1], pos.shape[2]
        if self.scene.pairs:
            pair_n, pair_tgt, pair_on = self._pairs(pos, vel)
        else:
            pair_n = pos.new_zeros(2, 0, N)
            pair_tgt = pos.new_zeros(2, 0, N)
            pair_on = torch.zeros(0, N, dtype=torch.bool, device=pos.device)
        normals, tgts, ons = [], [], []
        ones = pos.new_ones(B, N)
        for (nx, ny), (tgt, on) in zip(self._wall_n, self._walls(pos, vel)):
            normals.append(torch.stack((ones * nx, ones * ny)))
            tgts.append(tgt)
            ons.append(on)
        for shape in self.scene.obstacles:
            n, tgt, on = self._obstacle(shape, pos, vel)
            normals.append(n)
            tgts.append(tgt)
            ons.append(on)
        return Contacts(pair_n, pair_tgt, pair_on, torch.stack(normals), torch.stack(tgts), torch.stack(ons))

    # ---------------------------------------------------------------------------------------- impulses
    def solve(self, v: torch.Tensor, c: Contacts) -> torch.Tensor:
        """Sequential impulses on ``v`` = [2(channel), 2(xy), B, N] (velocity, bias velocity); returns it."""
        sc = self.scene
        eager = self.eager_skips and not torch.compiler.is_compiling()
        n_pairs = len(sc.pairs)
        walls = len(self._wall_n)
        group_on = None
        multi = None
        if eager or self.iterations > 1:
            counts = c.static_on.sum(0).to(v.dtype)
            if n_pairs:
                counts = counts + self.incidence @ c.pair_on.to(v.dtype)
            multi = (counts >= 2.0).any(0)  # [N]: some body of the env has two contacts at once
        if eager:
            flags = torch.cat((c.pair_on.any(1), c.static_on.flatten(1).any(1), multi.any().reshape(1)))
            group_on = flags.tolist()
        pair_acc = [v.new_zeros(2, v.shape[-1]) for _ in range(n_pairs)]
        static_acc = [v.new_zeros(2, v.shape[2], v.shape[3]) for _ in range(sc.n_static)]
        minv = sc.inv_mass
        for it in range(self.iterations):
            if it and eager and not group_on[-1]:
                break
            mask = multi if it else None
            for p, (a, b) in enumerate(sc.pairs):
                if eager and not group_on[p]:
                    continue
                n = c.pair_n[:, p]  # [2, N]
                rel = v[:, :, b] - v[:, :, a]  # [2ch, 2, N]
                vn = rel[:, 0] * n[0] + rel[:, 1] * n[1]
                jn = (c.pair_tgt[:, p] - vn) * (1.0 / (minv[a] + minv[b]))
                if mask is not None:
                    jn = torch.where(mask, jn, 0.0)
                new = torch.clamp(pair_acc[p] + jn, min=0.0)
                dj = new - pair_acc[p]
                pair_acc[p] = new
                imp = dj.unsqueeze(1) * n  # [2ch, 2, N]
                v[:, :, a] = v[:, :, a] - imp * minv[a]
                v[:, :, b] = v[:, :, b] + imp * minv[b]
            for s in range(sc.n_static):
                if eager and not group_on[n_pairs + s]:
                    continue
                tgt = c.static_tgt[s]  # [2ch, B, N]
                if s < walls:
                    v = self._wall_pass(v, s, tgt, static_acc, mask)
                    continue
                nx, ny = c.static_n[s, 0], c.static_n[s, 1]
                vn = -(v[:, 0] * nx + v[:, 1] * ny)
                jn = (tgt - vn) * self.static_nmass
                if mask is not None:
                    jn = torch.where(mask, jn, 0.0)
                new = torch.clamp(static_acc[s] + jn, min=0.0)
                dj = new - static_acc[s]
                static_acc[s] = new
                v = torch.stack((v[:, 0] - (dj * nx) * self.inv_mass, v[:, 1] - (dj * ny) * self.inv_mass), dim=1)
        return v

    def _wall_pass(self, v: torch.Tensor, s: int, tgt: torch.Tensor, acc: list[torch.Tensor],
                   mask: torch.Tensor | None) -> torch.Tensor:
        """A wall's pass: its normal is an axis, so one velocity component changes (exactly as the general
        formula, whose other terms are +-0)."""
        axis, sign = ((1, -1.0), (1, 1.0), (0, -1.0), (0, 1.0))[s]
        comp = v[:, axis]  # [2ch, B, N]
        vn = comp if sign < 0 else -comp
        jn = (tgt - vn) * self.static_nmass
        if mask is not None:
            jn = torch.where(mask, jn, 0.0)
        new = torch.clamp(acc[s] + jn, min=0.0)
        dj = new - acc[s]
        acc[s] = new
        comp = comp + dj * self.inv_mass if sign < 0 else comp - dj * self.inv_mass
        return torch.stack((comp, v[:, 1]) if axis == 0 else (v[:, 0], comp), dim=1)

    # -------------------------------------------------------------------------------------------- period
    def period(self, state: PhysicsState, wrench: torch.Tensor,
               impact_noise: torch.Tensor | None) -> tuple[PhysicsState, torch.Tensor, torch.Tensor]:
        """Advance ``scene.substeps`` substeps with body-frame wrenches ``wrench`` [3, R, N] (N, N, N m) held.

        ``impact_noise``: [substeps, n_robot_object_pairs, 2, N] velocity errors (m/s) an object gets when
        that robot-object contact ends in that substep, or None. Returns the new state and the number of
        contacts that ended in this period, per pair [P, N] and per static shape and body [S, B, N].
        """
        sc = self.scene
        dt = sc.dt_s
        R = sc.n_robots
        pos, vel, vbias, ang, omg, pair_on, static_on = state
        B, N = ang.shape
        fx, fy = wrench[0], wrench[1]
        dtorque = torch.cat((wrench[2] * self.inv_inertia_robot * dt, ang.new_zeros(B - R, N)))
        zeros_objects = ang.new_zeros(2, B - R, N)
        ended_pairs = torch.zeros(pair_on.shape, dtype=torch.int32, device=ang.device)
        ended_static = torch.zeros(static_on.shape, dtype=torch.int32, device=ang.device)
        for k in range(sc.substeps):
            c, s = torch.cos(ang[:R]), torch.sin(ang[:R])
            force = torch.cat((torch.stack((c * fx - s * fy, s * fx + c * fy)), zeros_objects), dim=1)
            pos = pos + (vel + vbias) * dt
            ang = ang + omg * dt
            contacts = self.detect(pos, vel)
            vel = vel + (force * self.inv_mass) * dt
            omg = omg + dtorque
            v = self.solve(torch.stack((vel, torch.zeros_like(vel))), contacts)
            vel, vbias = v[0], v[1]
            sep_pairs = pair_on & ~contacts.pair_on
            sep_static = static_on & ~contacts.static_on
            if impact_noise is not None:
                for q, (p, obj) in enumerate(sc.robot_object_pairs):
                    err = torch.where(sep_pairs[p], impact_noise[k, q], 0.0)  # [2, N]
                    vel = torch.cat((vel[:, :obj], (vel[:, obj] + err).unsqueeze(1), vel[:, obj + 1:]), dim=1)
            ended_pairs = ended_pairs + sep_pairs.to(torch.int32)
            ended_static = ended_static + sep_static.to(torch.int32)
            pair_on, static_on = contacts.pair_on, contacts.static_on
        return PhysicsState(pos, vel, vbias, ang, omg, pair_on, static_on), ended_pairs, ended_static
