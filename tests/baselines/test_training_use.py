"""Training that survives real use: progress without a terminal, the run folder, Ctrl-C and --resume, evaluations
in short runs, TensorBoard scalars of the task, model/scenario checks, rl_zoo3 folders, Minari infos."""

from __future__ import annotations

import base64
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from baselines.train import TrainConfig, train
from impact_env.cli import main
from tests.optional import requires
from tests.paths import DATA

pytestmark = requires("stable_baselines3")
MODELS = DATA / "models"  # copies of published folders of results/baselines/models/
TINY = """\
impact_env/ThrowAndCatchExp-v0:
  n_envs: 1
  n_timesteps: 1000000
  policy: 'MlpPolicy'
  normalize: true
  n_steps: 64
  batch_size: 64
  n_epochs: 1
  learning_rate: lin_3e-4
  policy_kwargs: "dict(net_arch=[16, 16])"
"""


@pytest.fixture(scope="module")
def tiny_yaml(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("hp") / "ppo_tiny.yml"
    path.write_text(TINY)
    return path


@pytest.fixture(scope="module")
def short_run(tiny_yaml, tmp_path_factory):
    """A 300-step run (PPO rounds it up to 320) into an explicit run folder, progress as lines (not a terminal)."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("runs") / "my_run"
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        run_dir = train(TrainConfig(algo="ppo", scenario="throw_and_catch_exp", timesteps=300, n_envs=1,
                                    out=str(out), hyperparams_file=str(tiny_yaml), eval_episodes=1))
    return run_dir, buffer.getvalue()


def test_out_is_the_run_folder_and_it_is_printed_first(short_run):
    run_dir, text = short_run
    assert run_dir.name == "my_run" and (run_dir / "model.zip").is_file()
    first = text.splitlines()[0]
    assert first.startswith(f"run folder: {run_dir}")
    assert "rounded up to whole rollouts of 64 steps" in text


def test_progress_is_plain_lines_when_not_on_a_terminal(short_run):
    _, text = short_run
    lines = [line for line in text.splitlines() if line.strip().startswith("step ")]
    assert lines and lines[-1].strip().startswith("step 320/320 (100%)")
    assert "\r" not in text  # no progress bar redraws in a log file


def test_a_short_run_is_evaluated_and_ends_with_an_evaluation(short_run, tmp_path):
    run_dir, _ = short_run
    meta = json.loads((run_dir / "train.json").read_text())
    assert meta["timesteps_trained"] == 320 and meta["interrupted"] is False
    with np.load(run_dir / "eval" / "evaluations.npz") as data:
        steps = data["timesteps"].tolist()
    assert len(steps) >= 4 and steps[-1] == 320
    assert main(["curves", str(run_dir), "--out", str(tmp_path / "c.png")]) == 0


def test_tensorboard_has_the_task_scalars(short_run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run_dir, _ = short_run
    tags = set()
    for events in (run_dir / "tb").rglob("events.out.tfevents.*"):
        acc = EventAccumulator(str(events))
        acc.Reload()
        tags |= set(acc.Tags()["scalars"])
    for prefix in ("rollout", "eval"):
        for name in ("robustness", "success_rate", "fuel_Ns", "impacts"):
            assert f"{prefix}/{name}" in tags, (prefix, name, sorted(tags))


def test_a_model_refuses_another_scenario_and_warns_about_other_options(short_run, tmp_path, capsys):
    from importlib.resources import files

    run_dir, _ = short_run
    model = str(run_dir / "model.zip")
    text = files("impact_env.transport.scenarios").joinpath("throw_and_catch_exp.toml").read_text()
    other = tmp_path / "wider_goal.toml"
    other.write_text(text.replace("2.1, 2.9", "2.0, 3.0"))  # the same observation size, another task
    assert text != other.read_text()
    assert main(["run", str(other), "--controller", model]) == 2
    assert "was trained on scenario 'throw_and_catch_exp'" in capsys.readouterr().err
    assert main(["run", str(other), "--controller", model, "--allow-other-scenario"]) == 0
    capsys.readouterr()
    assert main(["run", "throw_and_catch_exp", "--controller", model, "--thrust-noise", "0.05"]) == 0
    err = capsys.readouterr().err
    assert "trained with other environment options (thrust_noise: trained 0.0, flying 0.05)" in err
    assert main(["run", "throw_and_catch_exp", "--controller", model]) == 0
    assert "warning" not in capsys.readouterr().err


def _wait_for(proc: subprocess.Popen, needle: str, timeout_s: float) -> str:
    seen = ""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line and proc.poll() is not None:
            break
        seen += line
        if needle in line:
            return seen
    raise AssertionError(f"{needle!r} never appeared; output so far:\n{seen}")


def test_ctrl_c_saves_the_model_and_resume_continues_it(tiny_yaml, tmp_path):
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "impact_env.cli", "train", "ppo", "throw_and_catch_exp", "--timesteps", "100000000",
           "--n-envs", "2", "--hyperparams", str(tiny_yaml), "--out", str(run)]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    # the terminal's SIGINT, whatever this process inherited: a suite started in the background (`make test &`,
    # nohup) ignores SIGINT, a child inherits that, and Python then keeps Ctrl-C ignored
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            start_new_session=True, cwd=tmp_path,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_for(proc, "  step ", timeout_s=300)  # training has started
        os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole process group
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err, err
    assert "--resume" in out
    meta = json.loads((run / "train.json").read_text())
    assert meta["interrupted"] is True and meta["timesteps_trained"] >= 128
    assert (run / "model.zip").is_file() and (run / "vecnormalize.json").is_file()

    target = meta["timesteps_trained"] + 128
    assert main(["train", "ppo", "throw_and_catch_exp", "--timesteps", str(target), "--n-envs", "2",
                 "--hyperparams", str(tiny_yaml), "--out", str(run), "--resume", "--no-progress"]) == 0
    resumed = json.loads((run / "train.json").read_text())
    assert resumed["timesteps_trained"] == target and resumed["interrupted"] is False
    with np.load(run / "eval" / "evaluations.npz") as data:
        assert data["timesteps"].tolist()[-1] == target
    # resuming with other options is refused, not silently mixed
    assert main(["train", "ppo", "throw_and_catch_exp", "--timesteps", str(target + 128), "--n-envs", "2",
                 "--hyperparams", str(tiny_yaml), "--out", str(run), "--resume", "--thrust-noise", "0.1"]) == 2


def test_resume_needs_a_saved_run(tmp_path, capsys):
    assert main(["train", "ppo", "throw_and_catch_exp", "--out", str(tmp_path / "nothing"), "--resume"]) == 2
    assert "has no model.zip to continue" in capsys.readouterr().err


def test_effective_timesteps_are_whole_rollouts():
    from baselines.train import default_eval_freq, effective_timesteps

    assert effective_timesteps("ppo", 5_000, 2, {"n_steps": 4096}) == 8_192
    assert effective_timesteps("ppo", 8_192, 2, {"n_steps": 4096}) == 8_192
    assert effective_timesteps("ppo", 1_000, 1, {"n_steps": 64}, multiagent=True, n_agents=2) == 1_024
    assert effective_timesteps("sac", 1_001, 2, {}) == 1_002
    assert default_eval_freq(8_192) == 1_638 and default_eval_freq(10_000_000) == 20_000


def _with_entry(src: Path, dst: Path, key: str, pickle_bytes: bytes) -> None:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            raw = zin.read(item.filename)
            if item.filename == "data":
                data = json.loads(raw)
                data[key] = {":type:": "<class 'function'>", ":serialized:": base64.b64encode(pickle_bytes).decode()}
                raw = json.dumps(data).encode()
            zout.writestr(item, raw)


def test_rl_zoo3_models_get_a_clear_message(tmp_path, capsys):
    folder = tmp_path / "zoo"
    folder.mkdir()
    shutil.copy(MODELS / "ppo_throw_and_catch_exp" / "vecnormalize.json", folder)
    # rl_zoo3 pickles its learning-rate schedule, a function of rl_zoo3.utils (protocol-0 pickle of that global)
    _with_entry(MODELS / "ppo_throw_and_catch_exp" / "model.zip", folder / "model.zip", "learning_rate",
                b"crl_zoo3.utils\nlinear_schedule\n.")
    model = str(folder / "model.zip")
    # the safe loader rebuilds the schedule itself: rl_zoo3 is not needed to fly it
    assert main(["run", "throw_and_catch_exp", "--controller", model, "--allow-other-scenario"]) == 0
    capsys.readouterr()
    assert main(["run", "throw_and_catch_exp", "--controller", model, "--trust-pickle"]) == 2
    err = capsys.readouterr().err
    assert "saved by rl_zoo3" in err and "without --trust-pickle" in err

    # rl_zoo3's layout: <env>.zip beside <env>/vecnormalize.pkl; flying it without the statistics is refused
    zoo = tmp_path / "logs"
    (zoo / "ThrowAndCatchExp-v0").mkdir(parents=True)
    shutil.copy(MODELS / "ppo_throw_and_catch_exp" / "model.zip", zoo / "ThrowAndCatchExp-v0.zip")
    (zoo / "ThrowAndCatchExp-v0" / "vecnormalize.pkl").write_bytes(b"not read")
    assert main(["run", "throw_and_catch_exp", "--controller", str(zoo / "ThrowAndCatchExp-v0.zip")]) == 2
    err = capsys.readouterr().err
    assert "looks like an rl_zoo3 run" in err and "convert-model" in err


def test_minari_datasets_keep_infos_and_use_minari_s_default_path(tmp_path):
    pytest.importorskip("minari")
    home = tmp_path / "home"
    env = {k: v for k, v in os.environ.items() if k != "MINARI_DATASETS_PATH"}
    env["HOME"] = str(home)
    record = [sys.executable, "-m", "impact_env.cli", "record", "throw_and_catch_exp", "--episodes", "1"]
    subprocess.run(record, env=env, cwd=tmp_path, check=True, capture_output=True, timeout=600)
    assert (home / ".minari" / "datasets" / "impact_env" / "throw_and_catch_exp").is_dir()
    code = ("import minari, json\n"
            "ds = minari.load_dataset('impact_env/throw_and_catch_exp/expert-v0')\n"
            "ep = next(ds.iterate_episodes())\n"
            "print(json.dumps({k: [float(x) for x in v] for k, v in ep.infos.items()}))\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path, check=True, capture_output=True,
                         text=True, timeout=300).stdout
    infos = json.loads(out)
    assert set(infos) == {"robustness", "is_success", "impacts", "contacts", "fuel_Ns", "time_s"}
    assert all(len(v) == 201 for v in infos.values())  # the reset's and 200 steps'
    assert infos["robustness"][-1] == pytest.approx(0.4, abs=0.01) and infos["is_success"][-1] == 1.0
    assert sum(infos["impacts"]) == 2  # the expert's throw and catch
    assert infos["time_s"][-1] == pytest.approx(20.0)
