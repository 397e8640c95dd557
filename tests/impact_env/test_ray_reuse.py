"""A private local Ray instance is started once per process and reused by the next Ray engine
(``EngineConfig.keep_ray``): same Ray session, the same warm worker processes; another CPU count restarts it,
``keep_ray=False`` and :func:`impact_env.sweep.shutdown_ray` stop it."""

from __future__ import annotations

import importlib

import pytest

from impact_env import sweep
from impact_env.errors import EngineError
from impact_env.sweep import EngineConfig, open_engine, shutdown_ray
from tests import sweep_jobs
from tests.optional import requires

# one Ray instance at a time in the suite; ray looked up, not imported, while the suite is collected
pytestmark = [pytest.mark.xdist_group("ray"), requires("ray")]


def ray():
    """The ray module, imported when a test runs (collecting the suite does not need it)."""
    return importlib.import_module("ray")


@pytest.fixture(autouse=True)
def no_ray_before_or_after(monkeypatch):
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    if ray().is_initialized():
        ray().shutdown()
    yield
    shutdown_ray()
    if ray().is_initialized():
        ray().shutdown()


def _session() -> str:
    return ray().get_runtime_context().get_node_id()


def test_the_next_engine_reuses_the_kept_instance_and_its_workers():
    with open_engine(EngineConfig("ray", workers=1)) as engine:
        first = list(engine.map(sweep_jobs.worker_pid, [0, 1]))
        session = _session()
    assert ray().is_initialized()  # kept after the engine closed
    with open_engine(EngineConfig("ray", workers=1)) as engine:
        second = list(engine.map(sweep_jobs.worker_pid, [0, 1]))
        assert _session() == session
        assert "the private local instance this process keeps" in engine.describe()
    assert set(second) == set(first)  # the same warm worker (one CPU: one task process)
    assert shutdown_ray() and not ray().is_initialized()
    assert not shutdown_ray()  # nothing left to stop


def test_another_cpu_count_restarts_it_and_keep_ray_false_stops_it():
    with open_engine(EngineConfig("ray", workers=1)):
        session = _session()
    with open_engine(EngineConfig("ray", workers=2, keep_ray=False)) as engine:
        assert _session() != session and ray().cluster_resources()["CPU"] == 2
        assert list(engine.map(sweep_jobs.fail_on, [0, 1])) == [0, 1]
    assert not ray().is_initialized() and not sweep._kept_ray


def test_a_ray_started_elsewhere_is_used_and_left_running():
    ray().init(address="local", num_cpus=1, include_dashboard=False, logging_level="WARNING")
    session = _session()
    with open_engine(EngineConfig("ray", workers=2)) as engine:  # not ours: used as it is, whatever its size
        assert list(engine.map(sweep_jobs.fail_on, [0])) == [0]
    assert ray().is_initialized() and _session() == session and not shutdown_ray()


def test_keep_ray_must_be_a_flag():
    with pytest.raises(EngineError, match="keep_ray"):
        EngineConfig("ray", keep_ray="yes")
