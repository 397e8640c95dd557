"""A simulated two-node Ray cluster (``ray.cluster_utils.Cluster``: a head and a worker node, 1 CPU each, on this
machine): a bench sweep is spread over both nodes, gives the local table, and the workers run the code shipped
in the runtime environment (``--ship-code``) rather than the installed package."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

from impact_env.cli import main
from impact_env.sweep import EngineConfig, open_engine
from tests.optional import requires
from tests.paths import ROOT

# one Ray instance at a time (test_ray.py runs in the same worker)
pytestmark = [requires("ray"), pytest.mark.xdist_group("ray")]


@pytest.fixture(scope="module")
def cluster():
    import ray
    from ray.cluster_utils import Cluster

    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1, "include_dashboard": False})
    c.add_node(num_cpus=1)
    c.wait_for_nodes()
    yield c
    if ray.is_initialized():
        ray.shutdown()
    c.shutdown()


def _rows(path: Path) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "controller_ms"} for r in csv.DictReader(open(path))]


def test_a_bench_sweep_on_the_cluster_gives_the_local_table(cluster, tmp_path, capsys):
    """The bench's jobs are short: under load one node can finish all 8 before the other has started a
    worker (Ray's SPREAD is best effort), so where they ran is reported, not asserted; that jobs do reach
    both nodes is checked by test_shipped_code_runs_on_every_node, whose jobs last long enough."""
    import ray

    common = ["bench", "throw_and_catch_exp", "--controllers", "random,zero", "--episodes", "4",
              "--thrust-noise", "0.05", "--initial-position-noise-m", "0.05"]
    assert main(common + ["--engine", "ray", "--address", cluster.address, "--out", str(tmp_path / "cluster")]) == 0
    assert not ray.is_initialized()  # the bench connected, and disconnected at its end
    out = capsys.readouterr().out
    assert "Ray: 2 CPUs on 2 nodes (the cluster at" in out and re.search(r"8 jobs on [12] nodes? \(node ", out)
    assert main(common + ["--workers", "2", "--out", str(tmp_path / "local")]) == 0
    assert _rows(tmp_path / "cluster" / "episodes.csv") == _rows(tmp_path / "local" / "episodes.csv")


def test_shipped_code_runs_on_every_node(cluster, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # Ray puts the driver's working directory first on the workers' path

    def where_is_impact_env(_):  # a local function: sent by value (the workers cannot import tests/ from here)
        import time

        import impact_env

        time.sleep(0.5)  # long enough that one node cannot take every job before the other has a worker
        return impact_env.__file__

    with open_engine(EngineConfig("ray", address=cluster.address, ship_code=True)) as engine:
        files = list(engine.map(where_is_impact_env, [None] * 8))
        nodes = engine.nodes()
    assert len(nodes) == 2
    for path in files:  # Ray's copy of impact_env/, not this checkout's editable install
        assert "runtime_resources" in path and not Path(path).is_relative_to(ROOT)
