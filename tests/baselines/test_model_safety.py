"""Untrusted model folders run no code (issue 11): a malicious ``vecnormalize.pkl`` and a model zip with a
malicious pickled entry, built here, whose payload creates a marker file. ``run`` and ``bench`` refuse them
with an error naming ``--trust-pickle`` and the marker never appears; with the flag, the payload does run,
which shows the files really are malicious. (``bc`` is covered in test_baselines.py, next to its dataset.)"""

from __future__ import annotations

import base64
import json
import pickle
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest

from baselines import model_files
from impact_env.cli import main
from impact_env.errors import ModelFileError, UntrustedFileError
from tests.optional import requires
from tests.paths import DATA

pytestmark = requires("stable_baselines3")
MODELS = DATA / "models"  # copies of published folders of results/baselines/models/


class Payload:
    """Unpickling this calls open(marker, "w"): the marker file appears."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return open, (str(self.marker), "w")


def model_folder(tmp_path: Path, name: str = "bc_throw_and_catch_exp") -> Path:
    folder = tmp_path / "model"
    shutil.copytree(MODELS / name, folder)
    return folder


def with_malicious_pickle(folder: Path, marker: Path) -> Path:
    (folder / "vecnormalize.json").unlink()
    (folder / "vecnormalize.pkl").write_bytes(pickle.dumps(Payload(marker)))
    return folder / "model.zip"


def with_malicious_zip_entry(folder: Path, marker: Path, key: str, shape: int = 22) -> Path:
    """Rewrite model.zip with ``data[key]`` replaced by a serialized (cloudpickle-style) payload."""
    zip_path = folder / "model.zip"
    with zipfile.ZipFile(zip_path) as z:
        entries = {n: z.read(n) for n in z.namelist()}
    data = json.loads(entries["data"])
    data[key] = {":type:": "<class 'gymnasium.spaces.box.Box'>", "_shape": f"[{shape}]",
                 ":serialized:": base64.b64encode(pickle.dumps(Payload(marker))).decode()}
    entries["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(zip_path, "w") as z:
        for n, content in entries.items():
            z.writestr(n, content)
    return zip_path


def run(model: Path, *extra: str) -> list[str]:
    return ["run", "throw_and_catch_exp", "--controller", str(model), *extra]


def test_run_refuses_a_malicious_vecnormalize_pkl(tmp_path, capsys):
    marker = tmp_path / "marker"
    model = with_malicious_pickle(model_folder(tmp_path), marker)
    assert main(run(model)) == 2
    err = capsys.readouterr().err
    assert "vecnormalize.pkl is a pickle" in err and "--trust-pickle" in err and "convert-model" in err
    assert not marker.exists()
    assert main(run(model, "--trust-pickle")) == 2  # trusted, the payload runs (and holds no statistics)
    assert marker.exists()
    assert "does not hold VecNormalize statistics" in capsys.readouterr().err


def test_run_rebuilds_known_pickled_entries_without_decoding_them(tmp_path):
    """A payload hidden in the zip's observation_space: replaced by the env's space, never decoded."""
    marker = tmp_path / "marker"
    model = with_malicious_zip_entry(model_folder(tmp_path), marker, "observation_space")
    assert main(run(model, "--json", str(tmp_path / "run.json"))) == 0
    assert not marker.exists()
    assert json.loads((tmp_path / "run.json").read_text())["episodes"][0]["steps"] == 200


def test_run_refuses_an_unknown_pickled_entry(tmp_path, capsys):
    marker = tmp_path / "marker"
    model = with_malicious_zip_entry(model_folder(tmp_path), marker, "evil")
    assert main(run(model)) == 2
    err = capsys.readouterr().err
    assert "entry 'evil' is a pickle" in err and "--trust-pickle" in err
    assert not marker.exists()
    main(run(model, "--trust-pickle"))  # SB3's own loader unpickles every entry: the payload runs
    assert marker.exists()


@pytest.mark.parametrize("plant", ["pickle", "zip"])
def test_bench_refuses_malicious_folders_before_any_worker(tmp_path, capsys, plant):
    marker = tmp_path / "marker"
    folder = model_folder(tmp_path)
    model = with_malicious_pickle(folder, marker) if plant == "pickle" else \
        with_malicious_zip_entry(folder, marker, "evil")
    code = main(["bench", "throw_and_catch_exp", "--controllers", f"m:{model},zero", "--episodes", "1",
                 "--workers", "1", "--out", str(tmp_path / "bench")])
    assert code == 2 and "--trust-pickle" in capsys.readouterr().err
    assert not marker.exists() and not (tmp_path / "bench").exists()


def test_train_json_of_the_wrong_type_is_a_model_file_error(tmp_path, capsys):
    folder = model_folder(tmp_path)
    for content, message in (("[1, 2]", "must hold a JSON object"), ('{"algo": 3}', "algo must be one of"),
                             ('{"algo": [["ppo"]]}', "algo must be one of"),  # unhashable: found by the fuzzer
                             ('{"multiagent": "yes"}', "multiagent must be true or false"), ("{", "not valid JSON")):
        (folder / "train.json").write_text(content)
        with pytest.raises(ModelFileError, match=message):
            model_files.read_train_json(folder)
        assert main(run(folder / "model.zip")) == 2
        assert "train.json" in capsys.readouterr().err


def test_not_a_zip_and_a_model_for_another_scenario(tmp_path, capsys):
    folder = model_folder(tmp_path)
    (folder / "model.zip").write_bytes(b"not a zip")
    assert main(run(folder / "model.zip")) == 2
    assert "is not a model saved by stable-baselines3" in capsys.readouterr().err
    folder = model_folder(tmp_path / "other")
    with_malicious_zip_entry(folder, tmp_path / "marker", "observation_space", shape=29)
    assert main(run(folder / "model.zip")) == 2
    assert "observation space of shape (29,), but this scenario's is (22,)" in capsys.readouterr().err


def test_committed_models_hold_no_pickle_and_load_safely():
    for folder in sorted(MODELS.iterdir()):
        assert not list(folder.glob("*.pkl"))
        if not (folder / "model.zip").exists():  # an RLlib export: policy.json and .npz weights, no SB3 zip
            assert (folder / "policy.json").exists() and list(folder.glob("*.npz")), folder
            for weights in folder.glob("*.npz"):
                with np.load(weights, allow_pickle=False) as arrays:  # an object array would raise here
                    assert all(arrays[k].dtype != object for k in arrays.files)
            continue
        model_files.preflight(folder / "model.zip")  # every pickled zip entry is one the loader rebuilds
        stats = model_files.read_normalization(folder / "vecnormalize.json", obs_size=22)  # 3 bodies x 7 + 1
        assert stats.norm_obs and stats.clip_obs == 10.0


def test_convert_model_needs_the_flag_and_writes_json(tmp_path, capsys):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from impact_env.envs import TransportEnv

    folder = model_folder(tmp_path)
    (folder / "vecnormalize.json").unlink()
    venv = VecNormalize(DummyVecEnv([lambda: TransportEnv("throw_and_catch_exp")]))
    venv.obs_rms.mean += 0.1 + 1e-17 * (1 + venv.obs_rms.mean)
    venv.save(str(folder / "vecnormalize.pkl"))  # what train and bc wrote before
    assert main(["convert-model", str(folder)]) == 2
    assert "--trust-pickle" in capsys.readouterr().err and (folder / "vecnormalize.pkl").exists()
    assert main(["convert-model", str(folder), "--trust-pickle"]) == 0
    assert not (folder / "vecnormalize.pkl").exists()
    converted = model_files.read_normalization(folder / "vecnormalize.json", obs_size=22)
    assert converted.mean.tolist() == venv.obs_rms.mean.tolist() and converted.var.tolist() == venv.obs_rms.var.tolist()
    assert main(run(folder / "model.zip")) == 0


def test_untrusted_file_error_is_a_model_file_error():
    assert issubclass(UntrustedFileError, ModelFileError)
