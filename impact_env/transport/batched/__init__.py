"""The impact-transport world batched in torch: thousands of envs of one scenario in one array program.

:class:`BatchedTransportWorld` (``world.py``) is the API. The physics is chipmunk's substep scheme (the
scheme of the pymunk world this mirrors, :mod:`impact_env.transport.physics`) written as tensor ops
(``physics.py``, and ``fused.py`` for torch.compile), with Newton's exact restitution law for every contact;
the STL reward is the online monitor's recurrences over the env axis (``monitor.py``); noise comes from
counter-based Philox streams keyed by each env's seed (``philox.py``).

Why not a physics engine for the batch: pymunk (chipmunk) steps one space per Python call, so N envs cost N
calls per substep, which is the Gym env's speed, not a batch's; VMAS resolves contacts with penalty forces
(springs), so its impacts are soft pushes whose outcome depends on the spring constants, not the
restitution law the planner's impact model assumes (parity would fail by design); jax2d is a Box2D-style
impulse engine in JAX, but it would bring JAX next to torch (the RL stack's array library), its solver
differs from chipmunk's (so the parity bar would be met by neither), and it is built for rigid polygons with
friction and joints, much more than frictionless discs need. Written directly, the same contact law runs as
a few hundred pointwise operations per env and substep, which a compiler fuses into one loop.

Importing :mod:`impact_env` never imports torch; this package needs the ``[rl]`` extra.
"""

from impact_env.transport.batched.world import BatchedTransportWorld

__all__ = ["BatchedTransportWorld"]
