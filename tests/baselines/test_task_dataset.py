"""The dataset builder of generated tasks (baselines/task_dataset.py): ``impact-env dataset``.

Flies the two small generated tasks kept in tests/data/generated/ (written by ``impact-env filter``) with the
expert; no planning.
"""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from baselines.task_dataset import DatasetConfig, build_dataset, dataset_ids, is_heldout, split_tasks
from impact_env.cli import main
from impact_env.errors import ImpactEnvError
from impact_env.transport.generate import FAMILY_LIMITS, generate_task
from impact_env.transport.task_observation import TaskObservation
from tests.optional import requires
from tests.paths import DATA

pytestmark = requires("minari")  # looked up, not imported: the tests import it when they run

GENERATED = DATA / "generated"


def test_the_split_is_a_function_of_name_and_seed_only():
    names = [f"gaps_{i}" for i in range(200)]
    train, held = split_tasks(names, 0.2, split_seed=0)
    assert 20 <= len(held) <= 60 and set(train) | set(held) == set(names) and not set(train) & set(held)
    more_train, more_held = split_tasks(names + [f"gaps_{i}" for i in range(200, 400)], 0.2, split_seed=0)
    assert set(held) <= set(more_held) and set(train) <= set(more_train)  # tasks keep their side
    assert split_tasks(names, 0.2, split_seed=1)[1] != held
    assert all(is_heldout(n, 0.2) for n in held)
    # two tasks: one on each side, whatever their hashes
    assert [len(side) for side in split_tasks(["a", "b"], 0.01)] == [1, 1]
    assert [len(side) for side in split_tasks(["a", "b"], 0.99)] == [1, 1]


def test_config_errors():
    with pytest.raises(ImpactEnvError, match="heldout_share"):
        DatasetConfig(heldout_share=1.0)
    with pytest.raises(ImpactEnvError, match="episodes_per_task"):
        DatasetConfig(episodes_per_task=0)


def test_build_dataset_writes_both_sides_with_padded_spaces(tmp_path, monkeypatch):
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "ds"))  # restored after the test
    tasks = tmp_path / "tasks"
    shutil.copytree(GENERATED, tasks)
    assert main(["dataset", "--family", "throw_and_catch", "--tasks", str(tasks), "--out", str(tmp_path / "ds")]) == 0
    split = json.loads((tmp_path / "ds" / "impact_env" / "generated_throw_and_catch" / "split.json").read_text())
    assert sorted(split["train"] + split["heldout"]) == ["throw_and_catch_0", "throw_and_catch_2"]
    assert len(split["train"]) == len(split["heldout"]) == 1
    size = TaskObservation(generate_task("throw_and_catch", 0), FAMILY_LIMITS["throw_and_catch"]).size
    for dataset_id, names in zip(dataset_ids("throw_and_catch"), (split["train"], split["heldout"])):
        dataset = minari.load_dataset(dataset_id)
        (episode,) = list(dataset.iterate_episodes())
        seed = int(names[0].rsplit("_", 1)[1])
        sc = generate_task("throw_and_catch", seed)
        assert episode.observations.shape == (round(sc.tf_s / 0.1) + 1, size)
        assert episode.actions.shape == (round(sc.tf_s / 0.1), 12)
        assert np.all(episode.infos["task_seed"] == seed)
        assert not episode.actions[:, 3 * len(sc.robots):].any()  # the padding robots do nothing
        assert bool(episode.infos["is_success"][-1]) == split["episodes"][dataset_id][0]["success"]

    # behaviour cloning on it (baselines/task_bc.py): the saved policy acts on the padded layout, in [-1, 1]
    import torch

    from baselines.task_bc import TaskBCConfig, TaskBCPolicy, _network, train_task_bc

    run = train_task_bc(TaskBCConfig("throw_and_catch", datasets_dir=str(tmp_path / "ds"), epochs=2,
                                     out=str(tmp_path / "bc")))
    train = json.loads((run / "train.json").read_text())
    assert train["steps"] == round(generate_task("throw_and_catch", int(split["train"][0].rsplit("_", 1)[1])).tf_s
                                   / 0.1) and train["final_loss"] > 0
    policy = TaskBCPolicy.load(run)
    steps = next(minari.load_dataset(dataset_ids("throw_and_catch")[0]).iterate_episodes())
    assert train["train_mse"] == pytest.approx(np.mean((policy.act(steps.observations[:-1]) - steps.actions) ** 2),
                                               rel=1e-4)  # the clean fit, as the saved policy acts
    obs = minari.load_dataset(dataset_ids("throw_and_catch")[1]).sample_episodes(1)[0].observations[5]
    action = policy.act(obs)
    assert action.shape == (12,) and np.all(np.abs(action) <= 1) and np.array_equal(action, policy.act(obs))
    payload = torch.load(run / "policy.pt", weights_only=True)
    net = _network(payload["n_in"], payload["n_out"], tuple(payload["hidden"]))
    net.load_state_dict(payload["state_dict"])
    reference = net(torch.as_tensor((obs - policy.mean) / policy.std)[None]).detach().numpy()[0]
    assert np.allclose(action, reference, atol=1e-5)  # the numpy forward pass is the network's


def test_a_folder_with_too_few_tasks_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "ds"))
    tasks = tmp_path / "tasks"
    shutil.copytree(GENERATED, tasks)
    with pytest.raises(ImpactEnvError, match="1 kept throw_and_catch task"):
        build_dataset("throw_and_catch", tasks, DatasetConfig(max_tasks=1), out=tmp_path / "ds")
    with pytest.raises(ImpactEnvError, match="unknown task family"):
        build_dataset("nope", tasks, out=tmp_path / "ds")


def test_without_flying_the_heldout_side_only_the_training_tasks_are_in_a_dataset(tmp_path, monkeypatch):
    import minari

    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "ds"))
    tasks = tmp_path / "tasks"
    shutil.copytree(GENERATED, tasks)
    config = DatasetConfig(quiet=True, heldout_share=0.5)
    build_dataset("throw_and_catch", tasks, config, out=tmp_path / "ds")  # both sides, as before
    train, held = build_dataset("throw_and_catch", tasks, DatasetConfig(quiet=True, heldout_share=0.5,
                                                                        fly_heldout=False), out=tmp_path / "ds")
    assert held is None and dataset_ids("throw_and_catch")[1] not in minari.list_local_datasets()  # the old one too
    split = json.loads((tmp_path / "ds" / "impact_env" / "generated_throw_and_catch" / "split.json").read_text())
    assert split["fly_heldout"] is False and len(split["heldout"]) == 1
    assert list(split["episodes"]) == [dataset_ids("throw_and_catch")[0]]
    held_seed = int(split["heldout"][0].rsplit("_", 1)[1])
    seeds = {int(s) for ep in train.iterate_episodes() for s in ep.infos["task_seed"]}
    assert seeds == {int(split["train"][0].rsplit("_", 1)[1])} and held_seed not in seeds
    with pytest.raises(ImpactEnvError, match="fly_heldout"):
        DatasetConfig(fly_heldout=1)
