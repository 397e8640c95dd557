"""The substep as one pointwise program over [N] rows: what torch.compile fuses into a single CPU loop.

:class:`~impact_env.transport.batched.physics.ReferenceKernel` groups bodies and contacts into few large
tensor ops, which is what eager torch (and a GPU) runs fast. Inductor, on the other hand, fuses a program of
pointwise ops on rows of the same length into one loop over the envs, with every intermediate in registers;
an ``index_select`` or a slice assignment splits that loop. So this module writes the same arithmetic, in
the same order and with the same constants (bit-identical results, tested), once per body and contact.

One pass of impulses is done here. An env in which a body has two contacts at once, a disc centre is inside
an obstacle or two disc centres coincide is flagged in the returned ``redo`` mask, and the world redoes that
env's control period with the reference kernel (all passes, inside-shape normals). With random actions that
is a handful of envs per million substeps, so the fused loop never pays for the rare cases.
"""

from __future__ import annotations

import torch

from impact_env.transport.batched.physics import WALL_AXIS_SIGN, RowLayout
from impact_env.transport.batched.scene import BoxShape, Scene

_INF = float("inf")


class FusedKernel:
    """``substep(rows, ended, force, impact_noise) -> (rows, ended, redo)`` for one scene and dtype."""

    def __init__(self, scene: Scene, dtype: torch.dtype) -> None:
        self.scene = scene
        self.layout = RowLayout(scene.n_bodies, len(scene.pairs), scene.n_static)
        # the constants as the reference kernel's tensors hold them (rounded to dtype), so both round alike
        self.minv = torch.tensor(scene.inv_mass, dtype=dtype).tolist()
        self.static_nmass = (1.0 / torch.tensor(scene.inv_mass, dtype=dtype)).tolist()
        self.radius = torch.tensor(scene.radius_m, dtype=dtype).tolist()
        rsum = [scene.radius_m[a] + scene.radius_m[b] for a, b in scene.pairs]
        self.rsum = torch.tensor(rsum, dtype=dtype).tolist()
        self.rsum2 = torch.tensor([r * r for r in rsum], dtype=dtype).tolist()

    def _bias(self, gap: torch.Tensor) -> torch.Tensor:
        sc = self.scene
        return (-sc.bias_coef) * torch.clamp(gap + sc.slop_m, max=0.0) / sc.dt_s

    def substep(self, rows: torch.Tensor, ended: torch.Tensor, force: torch.Tensor,
                impact_noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Same arguments and results as ``ReferenceKernel.substep``, plus ``redo`` [N] bool (see module)."""
        sc, lay = self.scene, self.layout
        B, R = sc.n_bodies, sc.n_robots
        dt, e, minv = sc.dt_s, sc.restitution, self.minv
        r = list(rows.unbind(0))
        x, y, vx, vy, bx, by = (r[k * B:(k + 1) * B] for k in range(6))
        old_pair_on, old_static_on = r[lay.pair_on], r[lay.static_on]
        fx, fy = list(force[0].unbind(0)), list(force[1].unbind(0))
        x = [x[b] + (vx[b] + bx[b]) * dt for b in range(B)]
        y = [y[b] + (vy[b] + by[b]) * dt for b in range(B)]
        count: list[torch.Tensor | None] = [None] * B  # contacts per body, for the redo flag
        redo: torch.Tensor | None = None

        def flag(cond: torch.Tensor) -> None:
            nonlocal redo
            redo = cond if redo is None else redo | cond

        def touch(b: int, on: torch.Tensor) -> None:
            c = count[b]
            count[b] = on.to(rows.dtype) if c is None else c + on.to(rows.dtype)

        pairs = []
        for p, (i, j) in enumerate(sc.pairs):
            dx, dy = x[j] - x[i], y[j] - y[i]
            d2 = dx * dx + dy * dy
            on = d2 < self.rsum2[p]
            dist = torch.sqrt(d2)
            ok = dist > 0.0
            inv = torch.where(ok, 1.0 / dist, 0.0)
            nx, ny = torch.where(ok, dx * inv, 1.0), dy * inv
            vrn = (vx[j] - vx[i]) * nx + (vy[j] - vy[i]) * ny
            tv = torch.where(on, -(vrn * e), -_INF)
            tb = torch.where(on, self._bias(dist - self.rsum[p]), -_INF)
            pairs.append((i, j, nx, ny, tv, tb, on))
            touch(i, on)
            touch(j, on)
            flag(on & ~ok)
        walls: list[list[tuple[torch.Tensor, torch.Tensor, torch.Tensor]]] = []  # per wall: per body (tv, tb, on)
        xmin, xmax, ymin, ymax = sc.world_box
        for s in range(4):
            wall = []
            for b in range(B):
                dist, vn = ((y[b] - ymin, vy[b]), (ymax - y[b], -vy[b]), (x[b] - xmin, vx[b]), (xmax - x[b], -vx[b]))[s]
                on = dist <= self.radius[b]
                wall.append((torch.where(on, -(vn * e), -_INF),
                             torch.where(on, self._bias(dist - self.radius[b]), -_INF), on))
                touch(b, on)
            walls.append(wall)
        # per obstacle: per body (nx, ny, tv, tb, on)
        obstacles: list[list[tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]] = []
        for shape in sc.obstacles:
            group = []
            for b in range(B):
                if isinstance(shape, BoxShape):
                    dx = torch.clamp(x[b], shape.x0, shape.x1) - x[b]
                    dy = torch.clamp(y[b], shape.y0, shape.y1) - y[b]
                    d2 = dx * dx + dy * dy
                else:
                    from impact_env.transport.batched.physics import polygon_closest

                    dx, dy, d2 = polygon_closest(shape, x[b], y[b])
                outside = d2 > 0.0
                flag(~outside)
                dist = torch.sqrt(d2)
                inv = torch.where(outside, 1.0 / dist, 0.0)
                nx, ny = dx * inv, dy * inv
                vn = -(vx[b] * nx + vy[b] * ny)
                on = dist <= self.radius[b]
                group.append((nx, ny, torch.where(on, -(vn * e), -_INF),
                              torch.where(on, self._bias(dist - self.radius[b]), -_INF), on))
                touch(b, on)
            obstacles.append(group)
        for c in count:
            if c is not None:  # every body has one (it is tested against the four walls)
                flag(c >= 2.0)
        # thrust, then one pass of impulses; the bias velocities start at 0 (chipmunk resets them)
        for k in range(R):
            vx[k] = vx[k] + (fx[k] * minv[k]) * dt
            vy[k] = vy[k] + (fy[k] * minv[k]) * dt
        bx = [torch.zeros_like(x[0]) for _ in range(B)]
        by = [torch.zeros_like(x[0]) for _ in range(B)]
        for i, j, nx, ny, tv, tb, _ in pairs:
            nm = 1.0 / (minv[i] + minv[j])
            dv = torch.clamp((tv - ((vx[j] - vx[i]) * nx + (vy[j] - vy[i]) * ny)) * nm, min=0.0)
            db = torch.clamp((tb - ((bx[j] - bx[i]) * nx + (by[j] - by[i]) * ny)) * nm, min=0.0)
            ix, iy, jx, jy = dv * nx, dv * ny, db * nx, db * ny
            vx[i], vy[i] = vx[i] - ix * minv[i], vy[i] - iy * minv[i]
            vx[j], vy[j] = vx[j] + ix * minv[j], vy[j] + iy * minv[j]
            bx[i], by[i] = bx[i] - jx * minv[i], by[i] - jy * minv[i]
            bx[j], by[j] = bx[j] + jx * minv[j], by[j] + jy * minv[j]
        for s, wall in enumerate(walls):
            for b, (tv, tb, _) in enumerate(wall):
                nm = self.static_nmass[b]
                axis, sign = WALL_AXIS_SIGN[s]
                V, W = (vx, bx) if axis == 0 else (vy, by)
                dv = torch.clamp((tv - (V[b] if sign < 0 else -V[b])) * nm, min=0.0)
                db = torch.clamp((tb - (W[b] if sign < 0 else -W[b])) * nm, min=0.0)
                if sign < 0:
                    V[b], W[b] = V[b] + dv * minv[b], W[b] + db * minv[b]
                else:
                    V[b], W[b] = V[b] - dv * minv[b], W[b] - db * minv[b]
        for group in obstacles:
            for b, (nx, ny, tv, tb, _) in enumerate(group):
                nm = self.static_nmass[b]
                dv = torch.clamp((tv - -(vx[b] * nx + vy[b] * ny)) * nm, min=0.0)
                db = torch.clamp((tb - -(bx[b] * nx + by[b] * ny)) * nm, min=0.0)
                vx[b], vy[b] = vx[b] - (dv * nx) * minv[b], vy[b] - (dv * ny) * minv[b]
                bx[b], by[b] = bx[b] - (db * nx) * minv[b], by[b] - (db * ny) * minv[b]
        # contacts that ended: post-impact velocity errors and counts
        pair_on = [c[6].to(rows.dtype) for c in pairs]
        static_on = ([c[2].to(rows.dtype) for wall in walls for c in wall]
                     + [c[4].to(rows.dtype) for group in obstacles for c in group])
        sep = [(old > new).to(rows.dtype) for old, new in zip(old_pair_on + old_static_on, pair_on + static_on)]
        if impact_noise is not None:
            for q, (p, obj) in enumerate(sc.robot_object_pairs):
                hit = sep[p] > 0.5
                vx[obj] = vx[obj] + torch.where(hit, impact_noise[q, 0], 0.0)
                vy[obj] = vy[obj] + torch.where(hit, impact_noise[q, 1], 0.0)
        out = torch.stack(x + y + vx + vy + bx + by + pair_on + static_on)
        new_ended = ended + torch.stack(sep) if sep else ended
        return out, new_ended, redo if redo is not None else torch.zeros_like(x[0], dtype=torch.bool)
