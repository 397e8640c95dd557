"""Model folders that are damaged, tampered with or incomplete give typed errors with the real reason, and a
trained folder's statistics load as a real ``VecNormalize`` (issue 24).

- zip-level tampering: an encrypted-member bit, an unknown compression method, a member that inflates to
  1 GB (refused before it is read), a member whose declared size lies;
- the path itself: a folder, a FIFO (never opened: that would block), a symbolic-link loop, a dangling link;
- a folder without ``vecnormalize.json``: an error when ``train.json`` says the policy was normalised, a loud
  warning when there is no ``train.json``, nothing when ``train.json`` says ``"normalized": false``;
- :func:`baselines.model_files.load_vec_normalize` builds the wrapper SB3 users expect from ``VecNormalize.load``.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest

from baselines import model_files
from impact_env.cli import main
from impact_env.errors import ModelFileError
from tests.helpers import one_line_error
from tests.optional import requires
from tests.paths import DATA

pytestmark = requires("stable_baselines3")  # looked up, not imported: the tests import it when they run

MODELS = DATA / "models"


def folder_copy(tmp_path: Path, name: str = "bc_throw_and_catch_exp") -> Path:
    folder = tmp_path / "model"
    shutil.copytree(MODELS / name, folder)
    return folder


def patch_member(zip_path: Path, member: str, *, flag_bits: int | None = None, method: int | None = None,
                 file_size: int | None = None) -> None:
    """Rewrite fields of one member's local and central headers in place (what a tampering editor would do)."""
    raw = bytearray(zip_path.read_bytes())
    with zipfile.ZipFile(zip_path) as z:
        info = z.getinfo(member)
    local = info.header_offset
    assert raw[local:local + 4] == b"PK\x03\x04"
    central = raw.find(b"PK\x01\x02")  # the central directory's records: find this member's by its name
    while central >= 0:
        name_len = struct.unpack_from("<H", raw, central + 28)[0]
        if raw[central + 46:central + 46 + name_len].decode() == member:
            break
        central = raw.find(b"PK\x01\x02", central + 4)
    assert central >= 0
    for offset, base in ((6, local), (8, central)):  # general purpose flags: local +6, central +8
        if flag_bits is not None:
            struct.pack_into("<H", raw, base + offset, flag_bits)
        if method is not None:
            struct.pack_into("<H", raw, base + offset + 2, method)
    if file_size is not None:
        struct.pack_into("<I", raw, local + 22, file_size)
        struct.pack_into("<I", raw, central + 24, file_size)
    zip_path.write_bytes(bytes(raw))


def run_args(model: Path, *extra: str) -> list[str]:
    return ["run", "throw_and_catch_exp", "--controller", str(model), *extra]


@pytest.mark.parametrize("member", ["data", "policy.pth"])
def test_an_encrypted_member_is_a_model_file_error(tmp_path, member, capsys):
    model = folder_copy(tmp_path) / "model.zip"
    patch_member(model, member, flag_bits=0x1)
    with pytest.raises(ModelFileError, match=f"member '{member}' is encrypted"):
        model_files.read_zip_data(model)
    assert "is encrypted" in one_line_error(run_args(model), capsys)


def test_an_unknown_compression_method_is_a_model_file_error(tmp_path, capsys):
    model = folder_copy(tmp_path) / "model.zip"
    patch_member(model, "policy.pth", method=99)
    with pytest.raises(ModelFileError, match="compressed with method 99"):
        model_files.preflight(model)
    assert "method 99" in one_line_error(run_args(model), capsys)


def test_a_member_inflating_to_a_gigabyte_is_refused_unread(tmp_path, monkeypatch, capsys):
    model = folder_copy(tmp_path) / "model.zip"
    patch_member(model, "data", file_size=2**30)  # the declared size: nothing is inflated to learn it
    read = []
    monkeypatch.setattr(zipfile.ZipExtFile, "read", lambda self, n=-1: read.append(n) or b"")
    with pytest.raises(ModelFileError, match="inflates to 1,073,741,824 bytes"):
        model_files.read_zip_data(model)
    assert not read
    monkeypatch.undo()
    assert "inflates to 1,073,741,824 bytes" in one_line_error(run_args(model), capsys)


def test_a_real_zip_bomb_is_refused(tmp_path, monkeypatch):
    """A deflated member of zeros, smaller on disk than its inflated size by a factor of 1000 (limits scaled
    down so the test stays small)."""
    monkeypatch.setattr(model_files, "MAX_MEMBER_BYTES", 2**20)
    model = tmp_path / "model.zip"
    with zipfile.ZipFile(model, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("data", b"0" * 2**22)
    assert model.stat().st_size < 2**14
    with pytest.raises(ModelFileError, match="inflates to 4,194,304 bytes"):
        model_files.read_zip_data(model)


def test_a_data_member_larger_than_json_may_be_is_not_read_whole(tmp_path, monkeypatch):
    monkeypatch.setattr(model_files, "MAX_DATA_BYTES", 1000)
    model = tmp_path / "model.zip"
    with zipfile.ZipFile(model, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("data", b" " * 5000)
    with pytest.raises(ModelFileError, match="larger than 1,000 bytes"):
        model_files.read_zip_data(model)


def test_a_member_whose_declared_size_lies_is_a_model_file_error(tmp_path):
    model = folder_copy(tmp_path) / "model.zip"
    patch_member(model, "data", file_size=10)
    with pytest.raises(ModelFileError, match="not a model saved by stable-baselines3"):
        model_files.read_zip_data(model)


@pytest.mark.parametrize("kind, message", [
    ("folder", "is a folder, not a zip file"),
    ("fifo", "is a FIFO (named pipe), not a zip file"),
    ("loop", "is a loop of symbolic links"),
    ("dangling", "does not exist (a symbolic link to a missing file)"),
    ("missing", "does not exist"),
])
def test_a_model_path_that_is_not_a_file_says_what_it_is(tmp_path, kind, message, capsys):
    folder = tmp_path / "run"
    folder.mkdir()
    model = folder / "model.zip"
    if kind == "folder":
        model.mkdir()
    elif kind == "fifo":
        os.mkfifo(model)
    elif kind == "loop":
        os.symlink(folder / "b.zip", model)
        os.symlink(model, folder / "b.zip")
    elif kind == "dangling":
        os.symlink(folder / "gone.zip", model)
    with pytest.raises(ModelFileError, match=message.replace("(", r"\(").replace(")", r"\)")):
        model_files.check_model_path(model)
    assert message in one_line_error(run_args(model), capsys)
    code = main(["bench", "throw_and_catch_exp", "--controllers", f"m:{model}", "--episodes", "1",
                 "--out", str(tmp_path / "bench")])
    assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "bench").exists()


def test_a_run_folder_given_for_its_model_says_so(tmp_path, capsys):
    folder = folder_copy(tmp_path)
    err = one_line_error(run_args(folder), capsys)
    assert "is a run folder" in err and f"--controller {folder / 'model.zip'}" in err


# ------------------------------------------------------------------------------------ missing statistics


def test_missing_statistics_of_a_normalised_run_are_an_error(tmp_path, capsys):
    folder = folder_copy(tmp_path)
    (folder / "vecnormalize.json").unlink()
    err = one_line_error(run_args(folder / "model.zip"), capsys)
    assert "has no vecnormalize.json" in err and "raw observations" in err and '"normalized": false' in err
    with pytest.raises(ModelFileError, match="has no vecnormalize.json"):
        model_files.preflight(folder / "model.zip")
    assert main(["bench", "throw_and_catch_exp", "--controllers", f"m:{folder / 'model.zip'}",
                 "--out", str(tmp_path / "bench")]) == 2
    assert "has no vecnormalize.json" in capsys.readouterr().err


def test_a_run_trained_on_raw_observations_flies_quietly(tmp_path, capsys):
    folder = folder_copy(tmp_path)
    (folder / "vecnormalize.json").unlink()
    meta = json.loads((folder / "train.json").read_text())
    (folder / "train.json").write_text(json.dumps({**meta, "normalized": False}))
    assert main(run_args(folder / "model.zip", "--json", str(tmp_path / "r.json"))) == 0
    assert "raw observations" not in capsys.readouterr().err.lower()


def test_a_bare_model_without_statistics_warns_loudly(tmp_path, capsys):
    folder = folder_copy(tmp_path)
    (folder / "vecnormalize.json").unlink()
    (folder / "train.json").unlink()
    with pytest.warns(UserWarning, match="RAW observations"):
        assert main(run_args(folder / "model.zip", "--json", str(tmp_path / "r.json"))) == 0
    assert "impact-env: warning:" in capsys.readouterr().err


def test_train_and_bc_record_whether_they_normalised():
    import inspect

    from baselines import bc, train

    assert '"normalized": isinstance(venv, VecNormalize)' in inspect.getsource(train._save)
    assert '"normalized": True' in inspect.getsource(bc.behaviour_clone)


# ------------------------------------------------------------------------------------ VecNormalize loader


@pytest.mark.parametrize("name", ["ppo_corridor", "bc_throw_and_catch_exp"])
def test_load_vec_normalize_builds_the_real_wrapper(name):
    import gymnasium as gym
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    import impact_env
    from baselines.policy import SB3Controller

    folder = MODELS / name
    scenario = json.loads((folder / "train.json").read_text())["scenario"]
    env_id = next(i for i, s in impact_env.GYM_IDS.items() if s == scenario)
    venv = model_files.load_vec_normalize(folder, DummyVecEnv([lambda: gym.make(env_id)]))
    assert isinstance(venv, VecNormalize) and not venv.training and not venv.norm_reward
    stats = model_files.read_normalization(folder / "vecnormalize.json")
    np.testing.assert_array_equal(venv.obs_rms.mean, stats.mean)
    np.testing.assert_array_equal(venv.obs_rms.var, stats.var)
    assert venv.clip_obs == stats.clip_obs and venv.epsilon == stats.epsilon
    model = PPO.load(folder / "model.zip", env=venv, device="cpu")
    venv.seed(0)
    obs = venv.reset()
    raw = venv.get_original_obs()[0]
    np.testing.assert_allclose(obs[0], stats.apply(raw), rtol=1e-6)
    action, _ = model.predict(obs, deterministic=True)
    controller = SB3Controller(impact_env.load_scenario(scenario), folder / "model.zip")
    controller.reset(gym.make(env_id), 0)
    np.testing.assert_allclose(action[0], controller.act(raw, {}), rtol=1e-5, atol=1e-6)
    assert model_files.load_vec_normalize(folder / "vecnormalize.json", DummyVecEnv([lambda: gym.make(env_id)]),
                                          training=True).training


def test_load_vec_normalize_errors(tmp_path):
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv

    import impact_env  # noqa: F401

    def venv():
        return DummyVecEnv([lambda: gym.make("impact_env/Corridor-v0")])

    with pytest.raises(ModelFileError, match="does not exist"):
        model_files.load_vec_normalize(tmp_path, venv())
    (tmp_path / "vecnormalize.json").write_text((MODELS / "bc_throw_and_catch_exp" / "vecnormalize.json").read_text())
    with pytest.raises(ModelFileError, match="must be 29 finite numbers"):  # statistics of another observation size
        model_files.load_vec_normalize(tmp_path, _sized_venv(29))
    data = json.loads((MODELS / "ppo_corridor" / "vecnormalize.json").read_text())
    (tmp_path / "vecnormalize.json").write_text(json.dumps({**data, "ret_rms": "x"}))
    with pytest.raises(ModelFileError, match="ret_rms must be an object"):
        model_files.load_vec_normalize(tmp_path, venv())


def _sized_venv(size: int):
    """A vector env whose observations have ``size`` numbers (another scenario's statistics do not fit it)."""
    import gymnasium as gym
    from gymnasium import spaces
    from stable_baselines3.common.vec_env import DummyVecEnv

    class Sized(gym.Env):
        observation_space = spaces.Box(-1.0, 1.0, (size,), np.float32)
        action_space = spaces.Box(-1.0, 1.0, (6,), np.float32)

        def reset(self, *, seed=None, options=None):
            return np.zeros(size, np.float32), {}

        def step(self, action):
            return np.zeros(size, np.float32), 0.0, True, False, {}

    return DummyVecEnv([Sized])
