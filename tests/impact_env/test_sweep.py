"""The sweep engine's local processes (impact_env/sweep.py); the Ray engine is tested in test_ray.py."""

from __future__ import annotations

import argparse

import pytest

from impact_env.errors import EngineError, ScenarioError
from impact_env.sweep import EngineConfig, add_engine_arguments, engine_config, local_path, open_engine
from tests import sweep_jobs


def test_results_come_back_in_job_order_whatever_finishes_first():
    jobs = [(k, 0.1 * (3 - k)) for k in range(4)]  # the first job is the slowest
    with open_engine(EngineConfig("local", workers=2)) as engine:
        assert list(engine.map(sweep_jobs.square_after, jobs)) == [0, 1, 4, 9]
        assert len(engine.placements) == 4
        assert engine.placement_summary().startswith("4 jobs on 1 node")


def test_a_typed_error_in_a_worker_arrives_as_itself_and_any_other_names_the_job():
    with open_engine(EngineConfig("local", workers=2)) as engine:
        with pytest.raises(ScenarioError, match="job 2 is a bad scenario"):
            list(engine.map(sweep_jobs.fail_on, [0, 1, 2]))
        with pytest.raises(EngineError, match=r"job 4 of 4 failed in a worker process: ZeroDivisionError"):
            list(engine.map(sweep_jobs.fail_on, [0, 1, 1, 3]))


def test_local_workers_run_one_thread_each():
    with open_engine(EngineConfig("local", workers=1)) as engine:
        assert list(engine.map(sweep_jobs.threads, [None])) == [{"omp": "1", "torch": 1}]


def test_local_sharing_is_the_path_itself(tmp_path):
    (tmp_path / "model.zip").write_bytes(b"weights")
    with open_engine(EngineConfig("local", workers=1)) as engine:
        handle = engine.share(tmp_path)
        assert handle == str(tmp_path) and local_path(handle) == str(tmp_path)
        (result,) = engine.map(sweep_jobs.read_shared, [(handle, "model.zip")])
    assert result == {"path": str(tmp_path), "bytes": b"weights"}


@pytest.mark.parametrize("kwargs, message", [
    ({"name": "dask"}, "EngineConfig.name must be one of local, ray"),
    ({"workers": 0}, r"EngineConfig.workers must be None \(the CPU count\) or an integer >= 1"),
    ({"address": "auto"}, "--address applies to --engine ray"),
    ({"ship_code": True}, "--ship-code applies to --engine ray"),
])
def test_engine_options_are_checked(kwargs, message):
    with pytest.raises(EngineError, match=message):
        EngineConfig(**kwargs)


def test_engine_arguments_and_ray_address_from_the_environment(monkeypatch):
    parser = argparse.ArgumentParser()
    add_engine_arguments(parser, default_workers=3)
    config = engine_config(parser.parse_args(["--engine", "ray", "--ship-code"]))
    assert config == EngineConfig("ray", 3, None, True)
    monkeypatch.setenv("RAY_ADDRESS", "10.0.0.5:6379")
    assert config.resolved_address() == "10.0.0.5:6379" and "cluster at 10.0.0.5:6379" in config.describe()
    assert engine_config(parser.parse_args([])).describe() == "3 local worker processes"


def test_a_list_to_plan_takes_impact_scenarios_only(capsys):
    from impact_env.cli import main

    assert main(["plan", "corridor,L", "--workers", "1"]) == 2
    assert "plan tether stations one at a time (L)" in capsys.readouterr().err
