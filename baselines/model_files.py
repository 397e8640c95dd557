"""Model folders read without running code from them: ``model.zip``, ``vecnormalize.json``, ``train.json``.

A pickle runs whatever code it names when it is loaded, so a model folder from someone else must never be
unpickled. stable-baselines3's ``model.zip`` keeps the weights as ``.pth`` files, which it loads with
``torch.load(weights_only=True)`` (plain tensors only), but it also pickles (cloudpickle) some entries of its
``data`` JSON: the spaces, the policy class, schedules, buffers. :func:`load_model` rebuilds each of those
entries itself (SB3's ``custom_objects``: the spaces from the environment, the policy class from the
algorithm, constants for the training-only schedules), so no pickled entry is ever decoded, and refuses a
zip whose pickled entries it does not know. The observation-normalisation statistics are plain JSON
(``vecnormalize.json``, :func:`save_normalization`) rather than VecNormalize's pickle.

Older folders hold ``vecnormalize.pkl``. Loading it (or a zip with unknown pickled entries) needs
``trust_pickle=True`` (``--trust-pickle`` on the command line), which prints a warning; ``impact-env
convert-model DIR --trust-pickle`` rewrites such a folder once into the safe form.
"""

from __future__ import annotations

import errno
import json
import lzma
import math
import stat
import sys
import warnings
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.errors import ModelFileError, UntrustedFileError
from impact_env.results_store import write_atomic

NORMALIZATION_FILE = "vecnormalize.json"
LEGACY_NORMALIZATION_FILE = "vecnormalize.pkl"
FORMAT = "impact_env.vecnormalize/1"
TRUST_FLAG = "--trust-pickle"
# what a model zip may hold: SB3's zips are a few hundred kB (weights, optimiser state, a JSON of settings)
MAX_MEMBER_BYTES = 512 * 2**20
MAX_ZIP_BYTES = 1024 * 2**20
MAX_DATA_BYTES = 16 * 2**20
_COMPRESSIONS = {zipfile.ZIP_STORED: "stored", zipfile.ZIP_DEFLATED: "deflated", zipfile.ZIP_BZIP2: "bzip2",
                 zipfile.ZIP_LZMA: "lzma"}
# entries of a model zip's data JSON that SB3 pickles and that are rebuilt here; the rest are training state
_SPACES = ("observation_space", "action_space")
_SCHEDULES = {"lr_schedule": 0.0, "learning_rate": 0.0, "clip_range": 0.2, "clip_range_vf": None}
_TRAINING_ONLY = ("_last_obs", "_last_episode_starts", "_last_original_obs", "ep_info_buffer", "ep_success_buffer",
                  "rollout_buffer_class", "replay_buffer_class", "action_noise")
_POLICY_MODULES = {"ppo": "stable_baselines3.common.policies", "sac": "stable_baselines3.sac.policies"}


def warn_trusted(path: Path | str) -> None:
    print(f"impact-env: warning: unpickling {path} because of {TRUST_FLAG}: a pickle can run any code; "
          "use this only for files you made yourself", file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------------- train.json


def read_train_json(folder: Path) -> dict[str, Any]:
    """The run's ``train.json`` as a dict ({} when absent), its known fields type-checked."""
    path = folder / "train.json"
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_bytes())
    except (ValueError, RecursionError) as exc:
        raise ModelFileError(f"{path} is not valid JSON: {str(exc)[:200]}") from None
    if not isinstance(meta, dict):
        raise ModelFileError(f"{path} must hold a JSON object like {{\"algo\": \"ppo\", ...}}, got a "
                             f"{type(meta).__name__}")
    if "algo" in meta and not (isinstance(meta["algo"], str) and meta["algo"] in _POLICY_MODULES):
        raise ModelFileError(f"{path}: algo must be one of {', '.join(_POLICY_MODULES)}, got {meta['algo']!r}")
    if "multiagent" in meta and not isinstance(meta["multiagent"], bool):
        raise ModelFileError(f"{path}: multiagent must be true or false, got {meta['multiagent']!r}")
    if "env_options" in meta and not isinstance(meta["env_options"], dict):
        raise ModelFileError(f"{path}: env_options must be an object, got {meta['env_options']!r}")
    return meta


# ---------------------------------------------------------------------------------------------- normalisation


@dataclass(frozen=True)
class Normalization:
    """VecNormalize's observation statistics: obs -> clip((obs - mean) / sqrt(var + epsilon), +-clip_obs)."""

    mean: np.ndarray
    var: np.ndarray
    count: float
    clip_obs: float
    epsilon: float
    norm_obs: bool = True

    def apply(self, obs: np.ndarray) -> np.ndarray:
        if not self.norm_obs:
            return obs
        return np.clip((obs - self.mean) / np.sqrt(self.var + self.epsilon), -self.clip_obs, self.clip_obs)


def save_normalization(vec_normalize: Any, path: Path | str) -> Path:
    """Write a VecNormalize's statistics as plain JSON (floats round-trip exactly)."""
    def rms(r: Any) -> dict[str, Any]:
        return {"mean": np.asarray(r.mean, dtype=float).tolist(), "var": np.asarray(r.var, dtype=float).tolist(),
                "count": float(r.count)}

    vn = vec_normalize
    data = {"format": FORMAT, "norm_obs": bool(vn.norm_obs), "norm_reward": bool(vn.norm_reward),
            "clip_obs": float(vn.clip_obs), "clip_reward": float(vn.clip_reward), "gamma": float(vn.gamma),
            "epsilon": float(vn.epsilon), "obs_rms": rms(vn.obs_rms), "ret_rms": rms(vn.ret_rms)}
    return write_atomic(path, json.dumps(data, indent=1))


def _vector(value: Any, where: str, size: int | None) -> np.ndarray:
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ModelFileError(f"{where} must be a list of numbers") from None
    if array.ndim != 1 or (size is not None and array.shape != (size,)) or not np.all(np.isfinite(array)):
        raise ModelFileError(f"{where} must be {size or 'a list of'} finite numbers, got shape {array.shape}")
    return array


def _number(data: dict, key: str, where: str, positive: bool = False) -> float:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or (positive and not value > 0) or value < 0:
        raise ModelFileError(f"{where}.{key} must be a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
    return float(value)


def read_normalization(path: Path, obs_size: int | None = None) -> Normalization:
    """Read and check a ``vecnormalize.json``."""
    try:
        data = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError) as exc:
        raise ModelFileError(f"cannot read {path}: {str(exc)[:200]}") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT or not isinstance(data.get("obs_rms"), dict):
        raise ModelFileError(f"{path} is not a {FORMAT} file (written by impact-env train or bc)")
    rms = data["obs_rms"]
    mean = _vector(rms.get("mean"), f"{path}: obs_rms.mean", obs_size)
    var = _vector(rms.get("var"), f"{path}: obs_rms.var", len(mean))
    if np.any(var < 0):
        raise ModelFileError(f"{path}: obs_rms.var must be >= 0")
    norm_obs = data.get("norm_obs", True)
    if not isinstance(norm_obs, bool):
        raise ModelFileError(f"{path}: norm_obs must be true or false, got {norm_obs!r}")
    return Normalization(mean, var, _number(rms, "count", f"{path}: obs_rms"),
                         _number(data, "clip_obs", str(path), positive=True), _number(data, "epsilon", str(path)),
                         norm_obs)


def set_obs_statistics(vec: Any, mean: np.ndarray, var: np.ndarray, count: float) -> None:
    """Write the observation statistics (mean, var, count) of a VecNormalize over a Box observation space."""
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    rms = vec.obs_rms
    if not isinstance(rms, RunningMeanStd):  # a dict of them: a Dict observation space, which no env here has
        raise ModelFileError(f"observation statistics are for one Box observation space, got {type(rms).__name__}")
    rms.mean, rms.var, rms.count = mean, var, count


def load_vec_normalize(path: Path | str, venv: Any, training: bool = False) -> Any:
    """A stable-baselines3 ``VecNormalize`` around ``venv`` with the statistics of a ``vecnormalize.json``: what
    ``VecNormalize.load(path, venv)`` gives for SB3's pickle, from the plain JSON a run folder keeps.

    ``path`` is a run folder (``impact-env train``'s ``--out``) or the JSON file itself. The wrapper is built with
    the file's ``norm_obs``, ``norm_reward``, ``clip_obs``, ``clip_reward``, ``gamma`` and ``epsilon``, and its
    ``obs_rms`` and ``ret_rms`` are the file's. ``training=False`` (the default, as for evaluation) freezes the
    statistics; ``training=True`` keeps updating them, to continue training. Reward normalisation is switched off
    when ``training`` is False, as SB3's evaluation recipe does::

        venv = load_vec_normalize("runs/ppo_corridor_s0", DummyVecEnv([lambda: gym.make("impact_env/Corridor-v0")]))
        model = PPO.load("runs/ppo_corridor_s0/model.zip", env=venv)
    """
    from stable_baselines3.common.vec_env import VecNormalize

    path = Path(path)
    file = path / NORMALIZATION_FILE if path.is_dir() else path
    if not file.is_file():
        raise ModelFileError(f"{file} does not exist: a run folder keeps its observation statistics in "
                             f"{NORMALIZATION_FILE} (a run trained with normalize: false has none)")
    stats = read_normalization(file, int(np.prod(venv.observation_space.shape)))
    data = json.loads(file.read_bytes())
    where = str(file)
    ret = data.get("ret_rms") or {"mean": 0.0, "var": 1.0, "count": 1e-4}
    if not isinstance(ret, dict):
        raise ModelFileError(f"{file}: ret_rms must be an object with mean, var and count")
    ret_mean = _finite(ret.get("mean"), f"{where}: ret_rms.mean")
    ret_var = _number(ret, "var", f"{where}: ret_rms")
    ret_count = _number(ret, "count", f"{where}: ret_rms")
    norm_reward = data.get("norm_reward", True)
    if not isinstance(norm_reward, bool):
        raise ModelFileError(f"{file}: norm_reward must be true or false, got {norm_reward!r}")
    clip_reward = _number(data, "clip_reward", where, positive=True) if "clip_reward" in data else 10.0
    gamma = _number(data, "gamma", where) if "gamma" in data else 0.99
    vec = VecNormalize(venv, training=training, norm_obs=stats.norm_obs,
                       norm_reward=norm_reward and training, clip_obs=stats.clip_obs,
                       clip_reward=clip_reward, gamma=gamma, epsilon=stats.epsilon)
    set_obs_statistics(vec, stats.mean.copy(), stats.var.copy(), stats.count)
    vec.ret_rms.mean, vec.ret_rms.var, vec.ret_rms.count = np.float64(ret_mean), np.float64(ret_var), ret_count
    return vec


def _finite(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ModelFileError(f"{where} must be a finite number, got {value!r}")
    return float(value)


def _unpickle_normalization(path: Path) -> Normalization:
    import pickle

    warn_trusted(path)
    try:
        with open(path, "rb") as f:
            vn = pickle.load(f)  # noqa: S301 - only with --trust-pickle
        return Normalization(np.asarray(vn.obs_rms.mean, dtype=float), np.asarray(vn.obs_rms.var, dtype=float),
                             float(vn.obs_rms.count), float(vn.clip_obs), float(vn.epsilon), bool(vn.norm_obs))
    except Exception as exc:  # noqa: BLE001 - whatever the trusted pickle held, it is not usable statistics
        raise ModelFileError(f"{path} does not hold VecNormalize statistics: {type(exc).__name__}: "
                             f"{str(exc)[:200]}") from None


def missing_normalization(folder: Path) -> None:
    """What a model folder without observation statistics means, decided by its ``train.json``:

    - ``"normalized": false``: the policy was trained on raw observations; nothing to say;
    - any other ``train.json`` (``impact-env train`` and ``bc`` normalise unless the hyperparameters say
      ``normalize: false``, and record which since 0.3.0): a :class:`ModelFileError`, since the policy would
      fly on raw observations it never saw;
    - no ``train.json`` (a model trained elsewhere): a warning on stderr and as a ``UserWarning``.
    """
    meta = read_train_json(folder)
    if meta.get("normalized") is False:
        return
    if meta:
        raise ModelFileError(
            f"{folder} has no {NORMALIZATION_FILE}, but its train.json says the policy was trained on normalised "
            f"observations{'' if 'normalized' in meta else ' (impact-env train and bc normalise them by default)'}; "
            f"without the statistics it would fly on raw observations. Copy the run's {NORMALIZATION_FILE} beside "
            "model.zip, or, if the policy really was trained on raw observations, add \"normalized\": false to "
            f"{folder / 'train.json'}")
    message = (f"{folder} has no {NORMALIZATION_FILE} and no train.json: the policy flies on RAW observations. If "
               "it was trained with VecNormalize, save its statistics there (baselines.model_files."
               "save_normalization); if not, add a train.json with \"normalized\": false to silence this")
    print(f"impact-env: warning: {message}", file=sys.stderr, flush=True)
    warnings.warn(message, UserWarning, stacklevel=3)


def load_normalization(folder: Path, obs_size: int | None = None, trust_pickle: bool = False) -> Normalization | None:
    """The folder's observation statistics: ``vecnormalize.json``, else (trusted only) ``vecnormalize.pkl``; None
    for a policy trained on raw observations (see :func:`missing_normalization` for when that is allowed)."""
    safe, legacy = folder / NORMALIZATION_FILE, folder / LEGACY_NORMALIZATION_FILE
    if safe.is_file():
        return read_normalization(safe, obs_size)
    if not legacy.is_file():
        missing_normalization(folder)
        return None
    if not trust_pickle:
        raise UntrustedFileError(
            f"{legacy} is a pickle, which can run code when loaded, so it is not loaded. If you made it, convert "
            f"the folder once with `impact-env convert-model {folder} {TRUST_FLAG}`, or pass {TRUST_FLAG} to load "
            "it as it is")
    return _unpickle_normalization(legacy)


# ------------------------------------------------------------------------------------------------ model.zip


def check_model_path(path: Path) -> None:
    """``path`` is a regular file (or a link to one), else a :class:`ModelFileError` with the real reason: it does
    not exist, is a folder, a FIFO, a device or a socket, is a loop of symbolic links, or cannot be read. A FIFO
    is never opened (opening one for reading blocks until someone writes to it)."""
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        dangling = " (a symbolic link to a missing file)" if path.is_symlink() else ""
        raise ModelFileError(f"model file {str(path)!r} does not exist{dangling}") from None
    except OSError as exc:
        reason = "is a loop of symbolic links" if exc.errno == errno.ELOOP else f"cannot be read: {exc.strerror}"
        raise ModelFileError(f"model file {str(path)!r} {reason}") from None
    if stat.S_ISREG(mode):
        return
    kind = ("a folder" if stat.S_ISDIR(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
            "a socket" if stat.S_ISSOCK(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else
            "not a regular file")
    hint = " (give the model.zip inside it)" if stat.S_ISDIR(mode) and (path / "model.zip").is_file() else ""
    raise ModelFileError(f"model file {str(path)!r} is {kind}, not a zip file{hint}")


def check_zip_members(path: Path, archive: zipfile.ZipFile) -> None:
    """Every member of a model zip can be read safely: not encrypted, compressed by a method Python reads, and
    small enough to inflate (a member that inflates to :data:`MAX_MEMBER_BYTES` or the whole archive to
    :data:`MAX_ZIP_BYTES` is refused before it is read: a zip bomb would otherwise be read into memory whole)."""
    total = 0
    for info in archive.infolist():
        where = f"{path}: member {info.filename!r}"
        if info.flag_bits & 0x1:
            raise ModelFileError(f"{where} is encrypted; stable-baselines3 never encrypts a model, so the file was "
                                 "altered or is not a model")
        if info.compress_type not in _COMPRESSIONS:
            raise ModelFileError(f"{where} is compressed with method {info.compress_type}, which is not one of the "
                                 f"zip methods a model is saved with ({', '.join(_COMPRESSIONS.values())})")
        if info.file_size > MAX_MEMBER_BYTES:
            raise ModelFileError(f"{where} inflates to {info.file_size:,} bytes, more than the {MAX_MEMBER_BYTES:,} a "
                                 "model member may have; not read")
        total += info.file_size
    if total > MAX_ZIP_BYTES:
        raise ModelFileError(f"{path} inflates to {total:,} bytes in all, more than the {MAX_ZIP_BYTES:,} a model may "
                             "have; not read")


def read_zip_data(path: Path) -> dict[str, Any]:
    """The ``data`` JSON of an SB3 model zip, decoded as JSON only (no entry is unpickled); the path and every
    member checked first (:func:`check_model_path`, :func:`check_zip_members`)."""
    check_model_path(path)
    try:
        with zipfile.ZipFile(path) as archive:
            check_zip_members(path, archive)
            with archive.open("data") as member:
                raw = member.read(MAX_DATA_BYTES + 1)
    except ModelFileError:
        raise
    except (OSError, EOFError, zipfile.BadZipFile, KeyError, ValueError, RuntimeError, NotImplementedError,
            zlib.error, lzma.LZMAError) as exc:
        raise ModelFileError(f"{path} is not a model saved by stable-baselines3 (a zip with a 'data' entry): "
                             f"{type(exc).__name__}: {str(exc)[:200]}") from None
    if len(raw) > MAX_DATA_BYTES:
        raise ModelFileError(f"{path}: its 'data' entry is larger than {MAX_DATA_BYTES:,} bytes; not a model's")
    try:
        data = json.loads(raw)
    except (ValueError, RecursionError) as exc:
        raise ModelFileError(f"{path}: its 'data' entry is not JSON: {str(exc)[:200]}") from None
    if not isinstance(data, dict):
        raise ModelFileError(f"{path}: its 'data' entry must be a JSON object")
    return data


def pickled_entries(data: dict[str, Any]) -> list[str]:
    return sorted(k for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v)


def infer_algo(path: Path, data: dict[str, Any], hint: str | None) -> str:
    """ppo or sac: from train.json's ``algo`` if given, else from the policy class's recorded module."""
    recorded = data.get("policy_class", {})
    module = recorded.get("__module__") if isinstance(recorded, dict) else None
    algo = hint
    if algo is None:
        algo = next((a for a, m in _POLICY_MODULES.items() if m == module), None)
        if algo is None:
            raise ModelFileError(f"{path}: cannot tell whether it is a PPO or a SAC model (policy module {module!r}); "
                                 "add train.json with \"algo\"")
    elif module is not None and module != _POLICY_MODULES[algo]:
        raise ModelFileError(f"{path}: train.json says {algo}, but the policy class comes from {module!r}")
    return algo


def _rebuildable(key: str) -> bool:
    return key in ("policy_class", "train_freq") or key in _SPACES or key in _SCHEDULES or key in _TRAINING_ONLY


def _untrusted_entry(path: Path, key: str) -> UntrustedFileError:
    return UntrustedFileError(f"{path}: its entry {key!r} is a pickle that can run code when loaded, and impact-env "
                              f"cannot rebuild it safely; pass {TRUST_FLAG} to unpickle it (only for files you made "
                              "yourself)")


def preflight(path: Path, trust_pickle: bool = False) -> None:
    """Check a model folder before any worker loads it: train.json, the zip's data JSON, its pickled entries
    and the normalisation file. Reads JSON only; imports neither torch nor stable-baselines3."""
    meta = read_train_json(path.parent)
    data = read_zip_data(path)
    infer_algo(path, data, meta.get("algo"))
    check_rl_zoo3(path, data, trust_pickle)
    if trust_pickle:
        return
    for key in pickled_entries(data):
        if not _rebuildable(key):
            raise _untrusted_entry(path, key)
    safe, legacy = path.parent / NORMALIZATION_FILE, path.parent / LEGACY_NORMALIZATION_FILE
    if safe.is_file():
        read_normalization(safe)
    elif legacy.is_file():
        load_normalization(path.parent)  # raises UntrustedFileError naming the flag
    else:
        missing_normalization(path.parent)


def convert_folder(folder: Path) -> list[str]:
    """Rewrite an old model folder into the safe form: vecnormalize.pkl -> vecnormalize.json (the pickle is
    removed). Unpickles the old file, so only for folders you made; returns what was done."""
    done = []
    legacy = folder / LEGACY_NORMALIZATION_FILE
    if legacy.is_file():
        import pickle

        warn_trusted(legacy)
        with open(legacy, "rb") as f:
            vn = pickle.load(f)  # noqa: S301 - the caller passed --trust-pickle
        save_normalization(vn, folder / NORMALIZATION_FILE)
        back = read_normalization(folder / NORMALIZATION_FILE)
        if not (np.array_equal(back.mean, vn.obs_rms.mean) and np.array_equal(back.var, vn.obs_rms.var)):
            raise ModelFileError(f"{folder}: the converted statistics differ from the pickled ones")
        legacy.unlink()
        done.append(f"{legacy} -> {folder / NORMALIZATION_FILE}")
    model = folder / "model.zip"
    if model.is_file():
        unknown = [k for k in pickled_entries(read_zip_data(model)) if not _rebuildable(k)]
        if unknown:
            raise ModelFileError(f"{model}: entries {unknown} are pickles impact-env cannot rebuild; the folder "
                                 "still needs --trust-pickle")
        done.append(f"{model}: every pickled entry is rebuilt on load, nothing to change")
    return done


def safe_replacements(path: Path, data: dict[str, Any], algo: str, observation_space: Any,
                      action_space: Any) -> dict[str, Any]:
    """SB3 ``custom_objects`` for every pickled entry of the zip; UntrustedFileError for one it cannot rebuild."""
    from stable_baselines3 import PPO, SAC

    classes: dict[str, type[PPO] | type[SAC]] = {"ppo": PPO, "sac": SAC}
    cls = classes[algo]
    out: dict[str, Any] = {}
    for key in pickled_entries(data):
        if key == "policy_class":
            out[key] = cls.policy_aliases["MlpPolicy"]
        elif key in _SPACES:
            space = observation_space if key == "observation_space" else action_space
            shape = _recorded_shape(data[key])
            if shape is not None and shape != tuple(space.shape):
                raise ModelFileError(f"{path} was trained with {key.replace('_', ' ')} of shape {shape}, but this "
                                     f"scenario's is {tuple(space.shape)}: it is a model for another scenario")
            out[key] = space
        elif key in _SCHEDULES:  # only training reads these; predict() does not
            out[key] = _SCHEDULES[key]
        elif key in _TRAINING_ONLY:
            out[key] = None
        elif key == "train_freq":
            out[key] = 1
        else:
            raise _untrusted_entry(path, key)
    return out


def _recorded_shape(entry: dict[str, Any]) -> tuple[int, ...] | None:
    """The ``_shape`` SB3 writes as readable text beside a pickled space, e.g. ``"[22]"``."""
    try:
        shape = json.loads(entry.get("_shape", "null"))
    except (TypeError, ValueError):
        return None
    if isinstance(shape, list) and all(isinstance(n, int) for n in shape):
        return tuple(shape)
    return None


def rl_zoo3_entries(data: dict[str, Any]) -> list[str]:
    """Pickled entries of a model zip that name rl_zoo3's code (its schedules, wrappers): read from the pickles'
    bytes, which spell out module names, without unpickling anything."""
    import base64
    import binascii

    out = []
    for key in pickled_entries(data):
        try:
            raw = base64.b64decode(data[key][":serialized:"], validate=False)
        except (binascii.Error, TypeError, ValueError):
            continue
        if b"rl_zoo3" in raw:
            out.append(key)
    return out


def rl_zoo3_normalization(path: Path) -> Path | None:
    """The ``vecnormalize.pkl`` rl_zoo3 keeps in a folder named after the model (``<env>/vecnormalize.pkl`` beside
    ``<env>.zip``), when ``path`` is laid out that way and no converted statistics sit beside it."""
    candidate = path.parent / path.stem / LEGACY_NORMALIZATION_FILE
    if candidate.is_file() and not (path.parent / NORMALIZATION_FILE).is_file() \
            and not (path.parent / LEGACY_NORMALIZATION_FILE).is_file():
        return candidate
    return None


def check_rl_zoo3(path: Path, data: dict[str, Any], trust_pickle: bool) -> None:
    """A clear message for a model trained with rl_zoo3 that impact-env cannot fly as it is."""
    stats = rl_zoo3_normalization(path)
    if stats is not None:
        raise ModelFileError(
            f"{path} looks like an rl_zoo3 run: its observation statistics are in {stats}, a pickle, and the policy "
            f"would fly without them. Copy that file beside the model as {path.parent / LEGACY_NORMALIZATION_FILE} "
            f"and convert the folder once with `impact-env convert-model {path.parent} {TRUST_FLAG}` (only for runs "
            "you made yourself)")
    entries = rl_zoo3_entries(data)
    if trust_pickle and entries:
        import importlib.util

        if importlib.util.find_spec("rl_zoo3") is None:
            raise ModelFileError(
                f"{path} was saved by rl_zoo3: its entries {entries} are rl_zoo3 code, and rl_zoo3 is not installed, "
                f"so {TRUST_FLAG} cannot unpickle them. Load it without {TRUST_FLAG} (impact-env rebuilds schedules "
                "and spaces itself), or `pip install rl_zoo3`")


def load_model(path: Path, algo: str | None, observation_space: Any, action_space: Any,
               trust_pickle: bool = False) -> Any:
    """Load a PPO or SAC ``model.zip`` on the CPU without decoding any pickled entry (unless trusted)."""
    from stable_baselines3 import PPO, SAC

    data = read_zip_data(path)
    algo = infer_algo(path, data, algo)
    check_rl_zoo3(path, data, trust_pickle)
    classes: dict[str, type[PPO] | type[SAC]] = {"ppo": PPO, "sac": SAC}
    cls = classes[algo]
    if trust_pickle:
        warn_trusted(path)
        custom = None
    else:
        custom = safe_replacements(path, data, algo, observation_space, action_space)
        if algo == "sac":
            custom["buffer_size"] = 1  # SAC would allocate its whole replay buffer, which predict() never reads
    try:
        return cls.load(str(path), device="cpu", custom_objects=custom)
    except Exception as exc:  # noqa: BLE001 - torch, zipfile and SB3 raise many types for a broken file
        hint = ""
        if isinstance(exc, ModuleNotFoundError) and exc.name and exc.name.split(".")[0] == "rl_zoo3":
            hint = f" (saved by rl_zoo3: load it without {TRUST_FLAG}, or pip install rl_zoo3)"
        raise ModelFileError(f"{path} could not be loaded as a {algo.upper()} model: {type(exc).__name__}: "
                             f"{str(exc)[:300]}{hint}") from None
