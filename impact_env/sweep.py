"""Where a sweep's jobs run: local worker processes (the default) or a Ray cluster (``--engine ray``).

A sweep is a list of independent jobs (one seeded episode, one plan, one benchmark cell) and a module-level
function that turns one job into one result. ``Engine.map(fn, jobs)`` returns the results in the order of
the jobs, whichever worker ran them, so a table built from them is the same on either engine, bit for bit,
as long as ``fn`` depends on nothing but its job (columns that measure wall-clock time excepted)::

    with open_engine(EngineConfig("ray", address="auto")) as engine:
        rows = engine.map(run_one_episode, jobs)
    print(engine.placement_summary())  # e.g. "20 jobs on 2 nodes (node 3f2a1c: 10, node 9b8e77: 10)"

The two engines, what a worker needs on a cluster and its one thread: see :func:`open_engine`.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import multiprocessing
import os
import socket
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from impact_env.config_checks import check_choice, check_flag, check_integer, check_text
from impact_env.errors import EngineError, ImpactEnvError

ENGINES = ("local", "ray")
_THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
# the packages a shipped runtime environment carries (the ones that exist next to this one)
SHIPPED_PACKAGES = ("impact_env", "planners", "baselines")


@dataclass(frozen=True)
class EngineConfig:
    """How to run a sweep (``--engine``, ``--workers``, ``--address``, ``--ship-code``)."""

    name: str = "local"
    """``local`` (worker processes on this machine) or ``ray``."""
    workers: int | None = None
    """Local worker processes, or the CPUs of a private local Ray instance; None: the CPU count."""
    address: str | None = None
    """A running Ray cluster (``auto``, ``HOST:PORT``); None: ``$RAY_ADDRESS``, else a private instance."""
    ship_code: bool = False
    """Ship this checkout's packages to the Ray workers in Ray's runtime environment."""
    keep_ray: bool = True
    """A private local Ray instance stays up when the engine closes, for the next ``--engine ray`` engine of
    this process (with the same CPU count) to reuse: its start-up and its workers' imports are paid once per
    process. :func:`shutdown_ray` stops it early; Ray stops it when the process exits. False: stop it at
    close. A cluster connection is always closed."""

    def __post_init__(self) -> None:
        check_choice(self, "name", EngineError, ENGINES)
        check_integer(self, "workers", EngineError, low=1, none="the CPU count")
        check_text(self, "address", EngineError, none="$RAY_ADDRESS, else a private instance")
        check_flag(self, "ship_code", EngineError)
        check_flag(self, "keep_ray", EngineError)
        if self.name == "local" and (self.address or self.ship_code):
            option = "--address" if self.address else "--ship-code"
            raise EngineError(f"{option} applies to --engine ray, not to local processes")

    def describe(self) -> str:
        if self.name == "local":
            return f"{self.workers or os.cpu_count() or 1} local worker processes"
        where = self.resolved_address()
        return f"Ray ({'cluster at ' + where if where else f'a local instance with {self.workers or 2} CPUs'})"

    def resolved_address(self) -> str | None:
        return self.address or os.environ.get("RAY_ADDRESS") or None


def add_engine_arguments(parser: argparse.ArgumentParser, default_workers: int | None = None) -> None:
    """``--engine``, ``--address``, ``--workers`` and ``--ship-code`` on a sweep command or benchmark script."""
    group = parser.add_argument_group("where the jobs run")
    group.add_argument("--engine", choices=ENGINES, default="local",
                       help="local worker processes (default) or Ray tasks, on a local instance or a cluster")
    group.add_argument("--address", default=None, metavar="ADDR",
                       help="--engine ray: a running Ray cluster ('auto' for the one `ray start --head` started here, "
                            "HOST:PORT elsewhere; default $RAY_ADDRESS, else a private local instance)")
    group.add_argument("--workers", type=int, default=default_workers,
                       help="local processes, or the CPUs of a private local Ray instance (default: the CPU count)")
    group.add_argument("--ship-code", action="store_true",
                       help="--engine ray: send this checkout's impact_env, planners and baselines to the workers "
                            "in Ray's runtime environment (default: the workers import the installed package)")


def engine_config(args: argparse.Namespace) -> EngineConfig:
    """The :class:`EngineConfig` of parsed :func:`add_engine_arguments` options."""
    return EngineConfig(args.engine, args.workers, args.address, args.ship_code)


@dataclass(frozen=True)
class Placement:
    """Where one job ran: the node (Ray's node id, or the host name for local processes) and the process."""

    node: str
    pid: int


@dataclass(frozen=True)
class SharedFiles:
    """A file or folder sent to a Ray cluster's object store by :meth:`Engine.share`."""

    name: str
    digest: str  # of the contents: a worker writes each version once
    is_folder: bool
    ref: Any  # ray.ObjectRef of {relative path: bytes}


_MATERIALISED: dict[str, str] = {}


def local_path(handle: str | SharedFiles) -> str:
    """In a worker: the local path of a handle from :meth:`Engine.share`. Shared contents are written once per
    node, under the temporary folder, in a folder named by their digest (renamed into place whole, so workers
    of one node that race for it all end up reading one complete copy)."""
    if isinstance(handle, str):
        return handle
    if handle.digest not in _MATERIALISED:
        import shutil
        import tempfile

        import ray

        root = Path(tempfile.gettempdir()) / "impact_env_shared"
        final = root / handle.digest
        if not final.exists():
            root.mkdir(parents=True, exist_ok=True)
            staging = Path(tempfile.mkdtemp(prefix=f"{handle.digest}.", dir=root))
            for rel, data in ray.get(handle.ref).items():
                out = staging / handle.name / rel if handle.is_folder else staging / handle.name
                out.parent.mkdir(parents=True, exist_ok=True)
                out.write_bytes(data)
            try:
                staging.rename(final)
            except OSError:  # another worker was first
                shutil.rmtree(staging, ignore_errors=True)
        _MATERIALISED[handle.digest] = str(final / handle.name)
    return _MATERIALISED[handle.digest]


def _located(fn: Callable[[Any], Any], job: Any) -> tuple[Any, Placement]:
    """Run ``fn(job)`` and say where (module level, so both engines can send it to a worker)."""
    node = socket.gethostname()
    try:
        import ray

        if ray.is_initialized():
            node = ray.get_runtime_context().get_node_id()
    except ImportError:
        pass
    return fn(job), Placement(node, os.getpid())


def _one_thread() -> None:
    for name in _THREAD_VARIABLES:
        os.environ[name] = "1"
    import sys

    if "torch" in sys.modules:  # imported by the main module of a spawned worker before this runs
        sys.modules["torch"].set_num_threads(1)


@dataclass
class Engine:
    """An open engine (see :func:`open_engine`); :meth:`map` runs a sweep, :attr:`placements` says where."""

    config: EngineConfig
    placements: list[Placement] = field(default_factory=list)
    _pool: ProcessPoolExecutor | None = None
    _pool_workers: int = 0  # the pool's processes
    _owns_ray: bool = False  # this engine called ray.init, so it calls ray.shutdown

    def map(self, fn: Callable[[Any], Any], jobs: Iterable[Any]) -> Iterator[Any]:
        """``fn(job)`` for every job, yielded in the jobs' order as soon as each (and all before it) is done.

        ``fn`` must be a module-level function (workers import it by name; a script's functions travel by value
        to Ray's workers). A job that raises on a worker raises here: an :class:`ImpactEnvError` as itself,
        anything else as an :class:`EngineError` naming the job's position and the worker's error.
        """
        jobs = list(jobs)
        if self.config.name == "local":
            yield from self._map_local(fn, jobs)
        else:
            yield from self._map_ray(fn, jobs)

    def _map_local(self, fn, jobs):
        assert self._pool is not None, "use the engine inside `with open_engine(...)`"
        futures = [self._pool.submit(_located, fn, job) for job in jobs]
        for k, future in enumerate(futures):
            try:
                result, where = future.result()
            except ImpactEnvError:
                raise
            except Exception as exc:
                for f in futures:
                    f.cancel()
                raise EngineError(f"job {k + 1} of {len(jobs)} failed in a worker process: "
                                  f"{type(exc).__name__}: {exc}") from exc
            self.placements.append(where)
            yield result

    def _map_ray(self, fn, jobs):
        import ray
        from ray.exceptions import RayError, RayTaskError

        remotes = _remotes_of(ray)
        if fn not in remotes:
            def run(job):
                return _located(fn, job)

            # one remote function per job function and Ray session: Ray sends it to each worker once and keeps
            # it there, so module-level caches of a script's function (sent by value) live as long as the
            # worker, across map calls and engines, as in a local pool
            run.__name__ = run.__qualname__ = getattr(fn, "__name__", "job")
            remotes[fn] = ray.remote(num_cpus=1, scheduling_strategy="SPREAD", max_retries=0)(run)
        refs = [remotes[fn].remote(job) for job in jobs]
        for k, ref in enumerate(refs):
            try:
                result, where = ray.get(ref)
            except RayTaskError as exc:
                for r in refs[k + 1:]:
                    ray.cancel(r)
                cause = getattr(exc, "cause", None)
                if isinstance(cause, ImpactEnvError):
                    raise cause from None
                raise EngineError(f"job {k + 1} of {len(jobs)} failed on a Ray worker: "
                                  f"{type(cause).__name__ if cause else 'error'}: {cause or exc}") from None
            except RayError as exc:  # a worker or node died, the object was lost
                raise EngineError(f"job {k + 1} of {len(jobs)} was lost on the Ray cluster: {exc}") from None
            self.placements.append(where)
            yield result

    def share(self, path: str | Path, include: Iterable[str] | None = None) -> str | SharedFiles:
        """A handle to a file or folder that every worker can read with :func:`local_path`: the path itself for
        local processes; for Ray, the contents (of a folder: the files named in ``include``, or all), put once
        into the cluster's object store, since a file on the driver's disk is not on the other nodes' disks."""
        path = Path(path)
        if self.config.name == "local":
            return str(path)
        import ray

        if path.is_dir():
            names = set(include) if include is not None else None
            files = {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*"))
                     if p.is_file() and (names is None or p.name in names)}
        else:
            files = {path.name: path.read_bytes()}
        digest = hashlib.sha256(path.name.encode() + b"".join(b"\0" + k.encode() + b"\0" + v
                                                           for k, v in files.items())).hexdigest()[:16]
        return SharedFiles(path.name, digest, path.is_dir(), ray.put(files))

    def describe(self) -> str:
        """E.g. ``2 local worker processes`` or ``Ray: 4 CPUs on 2 nodes (the cluster at 'auto')``."""
        if self.config.name == "local":
            return f"{self._pool_workers if self._pool else self.config.workers} local worker processes"
        import ray

        nodes = sum(1 for n in ray.nodes() if n.get("Alive"))
        where = self.config.resolved_address()
        where = (f"the cluster at {where!r}" if where and self._owns_ray else
                 "a private local instance" if self._owns_ray else
                 "the private local instance this process keeps" if _kept_ray else
                 "the Ray instance this process had started")
        return (f"Ray: {ray.cluster_resources().get('CPU', 0):g} CPUs on {nodes} node{'s' if nodes != 1 else ''} "
                f"({where})")

    def nodes(self) -> list[str]:
        """The distinct nodes the jobs so far ran on, in order of first use."""
        return list(dict.fromkeys(p.node for p in self.placements))

    def placement_summary(self) -> str:
        """E.g. ``20 jobs on 2 nodes (node 3f2a1c: 12, node 9b8e77: 8), 4 worker processes``."""
        counts = collections.Counter(p.node for p in self.placements)
        nodes = ", ".join(f"node {n[:6]}: {c}" for n, c in counts.items())
        processes = len({(p.node, p.pid) for p in self.placements})
        return (f"{len(self.placements)} jobs on {len(counts)} node{'s' if len(counts) != 1 else ''} ({nodes}), "
                f"{processes} worker process{'es' if processes != 1 else ''}")

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        if self._owns_ray:
            import ray

            ray.shutdown()  # a private instance stops; a cluster only loses this driver
            self._owns_ray = False

    def __enter__(self) -> Engine:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_engine(config: EngineConfig | None = None, n_jobs: int | None = None) -> Engine:
    """Start the engine ``config`` describes (local: a process pool of at most ``n_jobs`` workers; ray: connect
    to the cluster or start a private local instance). Use it as a context manager.

    Engines:

    - ``local``: a pool of ``workers`` spawned processes on this machine (spawn, not fork: a forked worker
      inherits the parent's solver and torch thread-pool locks and can deadlock on its first solve).
    - ``ray``: one Ray task per job (1 CPU each, scheduled with Ray's SPREAD strategy, so a cluster's nodes
      share the sweep even while the head node has free CPUs). ``address`` (or the ``RAY_ADDRESS`` environment
      variable) names a running cluster: ``auto`` for the one started on this machine with ``ray start --head``,
      ``HOST:6379`` for a head elsewhere. Without an address a private local Ray instance with ``workers`` CPUs
      is started, and kept when the ``with`` block ends for the next Ray engine of the process to reuse
      (``EngineConfig.keep_ray``; :func:`shutdown_ray` stops it, and so does the end of the process).

    Workers must import this package. On a cluster either install it on every node (``pip install
    impact_env[ray]`` into the same Python version as the driver's), or pass ``ship_code=True``
    (``--ship-code``): the driver's own ``impact_env``, ``planners`` and ``baselines`` folders then travel in
    Ray's runtime environment (``py_modules``) and shadow whatever is installed on the nodes. Their third-party
    dependencies (pymunk, casadi, highspy, ...) must be installed on the nodes either way.

    Both engines give each worker one thread for OpenMP and torch (Ray does this for 1-CPU tasks; the local
    pool sets ``OMP_NUM_THREADS=1`` and ``torch.set_num_threads(1)``), so a worker's floating-point results do
    not depend on the engine's threading, and ``workers`` processes use ``workers`` cores.
    """
    config = config or EngineConfig()
    engine = Engine(config)
    if config.name == "local":
        workers = config.workers or os.cpu_count() or 1
        if n_jobs is not None:
            workers = max(1, min(workers, n_jobs))
        engine._pool = ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                                           initializer=_one_thread)
        engine._pool_workers = workers
        return engine
    engine._owns_ray = connect_ray(config)
    return engine


def runtime_env(ship_code: bool) -> dict[str, Any] | None:
    """Ray's runtime environment for the workers: this checkout's packages as ``py_modules`` if ``ship_code``."""
    if not ship_code:
        return None
    root = Path(__file__).resolve().parent.parent
    modules = [str(root / name) for name in SHIPPED_PACKAGES if (root / name / "__init__.py").is_file()]
    # results/ holds published models and figures (megabytes) that no worker reads
    return {"py_modules": modules, "excludes": ["__pycache__", "*.pyc", "results/"]}


# The private local Ray instance this process keeps for reuse (EngineConfig.keep_ray): {"num_cpus": n, "session":
# the Ray session it belongs to}; empty when there is none.
_kept_ray: dict[str, Any] = {}
# Ray remote functions of the current Ray session: {"session": ..., "remotes": {job function: remote function}}
_session_remotes: dict[str, Any] = {}


def _session(ray: Any) -> tuple[str, str]:
    """This driver's Ray session: a new local instance has a new node id (job ids restart with each one)."""
    context = ray.get_runtime_context()
    return context.get_node_id(), context.get_job_id()


def _remotes_of(ray: Any) -> dict:
    """The remote functions made in this Ray session (a new session, after a shutdown, starts with none)."""
    session = _session(ray)
    if _session_remotes.get("session") != session:
        _session_remotes.clear()
        _session_remotes.update(session=session, remotes={})
    return _session_remotes["remotes"]


def shutdown_ray() -> bool:
    """Stop the private local Ray instance this process keeps (:attr:`EngineConfig.keep_ray`), if any: its
    raylet, object store and idle workers hold memory until then. Returns whether there was one. A Ray that
    someone else initialised is left alone."""
    if not _kept_ray:
        return False
    import ray

    if ray.is_initialized() and _session(ray) == _kept_ray["session"]:
        ray.shutdown()
    _kept_ray.clear()
    return True


def _private_cpus(config: EngineConfig, num_cpus: int | None) -> int:
    return num_cpus or config.workers or min(2, os.cpu_count() or 1)


def connect_ray(config: EngineConfig, num_cpus: int | None = None) -> bool:
    """Initialise Ray for ``config`` (connect to its cluster, or start a private local instance with ``num_cpus``
    or ``config.workers`` CPUs); returns True if it called ``ray.init`` and the caller is to call
    ``ray.shutdown``. An already initialised Ray (a notebook, a test fixture) is used as it is, and False
    returned. A private instance with ``config.keep_ray`` is kept for the rest of the process instead (False is
    returned): the next call reuses it if it has the CPU count asked for, else restarts it with that count."""
    try:
        import ray
    except ImportError:
        raise EngineError("--engine ray needs Ray: pip install 'impact_env[ray]'") from None
    address = config.resolved_address()
    if _kept_ray and not (ray.is_initialized() and _session(ray) == _kept_ray["session"]):
        _kept_ray.clear()  # someone called ray.shutdown
    if _kept_ray:
        if address is None and not config.ship_code and _private_cpus(config, num_cpus) == _kept_ray["num_cpus"]:
            return False
        shutdown_ray()  # another count, a cluster or shipped code: this instance does not serve
    if ray.is_initialized():
        if config.ship_code:  # Ray uploads local folders only for a job's own runtime environment (ray.init)
            raise EngineError("--ship-code needs to start the Ray connection itself, but Ray is already initialised "
                              "in this process: call ray.init(runtime_env=impact_env.sweep.runtime_env(True)) "
                              "yourself, or leave Ray uninitialised")
        return False
    options: dict[str, Any] = {"runtime_env": runtime_env(config.ship_code), "logging_level": "WARNING",
                               "configure_logging": True}
    if address is None:
        options.update(num_cpus=_private_cpus(config, num_cpus), include_dashboard=False)
    try:
        # "local", not None: with None, Ray joins a `ray start` cluster it finds recorded on this machine
        # (/tmp/ray/ray_current_cluster), which is someone else's on a shared machine
        ray.init(address=address or "local", **options)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        where = f"the Ray cluster at {address!r}" if address else "a local Ray instance"
        hint = (" (start one with `ray start --head`, or leave out --address and RAY_ADDRESS for a private local "
                "instance)" if address else "")
        raise EngineError(f"could not connect to {where}: {str(exc).splitlines()[0][:300]}{hint}") from None
    if address is None and config.keep_ray and not config.ship_code:
        _kept_ray.update(num_cpus=options["num_cpus"], session=_session(ray))
        return False
    return True
