"""Property-based fuzzing of what a user hands in besides the worlds' own inputs: STL text with runs of white
space and extreme numbers, plan files of every kind mutated byte by byte, model folders mutated at the zip level,
and output paths of every kind (issue 24).

The invariant of tests/fuzz/invariant.py: every input works or raises one of the package's typed errors within
the CPU-time deadline. What works must also be right: an STL formula prints back to itself and its online
monitor agrees with its offline robustness; an accepted plan file passes its checks and is finite; an accepted
model folder gives a controller whose actions are finite and in bounds; an output path that passes its check can
be written, and holds what was written; a command given an unwritable path says so before any work. Sizes as in
test_fuzz.py: :data:`DEFAULT_EXAMPLES` derandomized inputs per fuzzer by default, fresh ones for
``IMPACT_ENV_FUZZ_SECONDS`` each with ``-m slow`` (``make fuzz``).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import shutil
import struct
import tempfile
import uuid
import warnings
import zipfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import strategies as st

from impact_env.errors import OutputPathError
from impact_env.results_store import check_output_file, check_output_folder, write_atomic
from impact_env.stl import OnlineMonitor, parse, robustness
from impact_env.tether.station import load_station
from impact_env.transport.scenario import load_scenario, scenario_from_dict
from planners.plan import Plan
from planners.tether.plan import TetherPlan, is_tether_plan_file
from tests.fuzz import strategies as S
from tests.fuzz.invariant import COUNTS, assert_finite, attempt, cpu_deadline, fuzz_fixed, fuzz_for_budget
from tests.fuzz.test_fuzz import fly_scenario
from tests.paths import DATA

DEFAULT_EXAMPLES = {"stl_extremes": 150, "plan_bytes": 100, "model_folder": 40, "output_path": 150}
ROUND = {"stl_extremes": 100, "plan_bytes": 50, "model_folder": 20, "output_path": 50}  # per round of the slow run
_TMP = Path(tempfile.mkdtemp(prefix="impact_env_files_fuzz_"))
_TRACE = {"O1": np.linspace([1.0, 2.0], [1.0, 8.0], 31), "R1": np.tile([1.0, 1.0], (31, 1)),
          "R2": np.tile([1.0, 9.0], (31, 1))}
_REGIONS = load_scenario("corridor").region_map()


def teardown_module() -> None:
    shutil.rmtree(_TMP, ignore_errors=True)


def _fresh(suffix: str = "") -> Path:
    return _TMP / f"{uuid.uuid4().hex}{suffix}"


# ------------------------------------------------------------------------------------ STL: spaces, numbers


def stl_extremes(text: str) -> None:
    formula = attempt("stl_extremes", lambda: parse(text))
    if formula is None:
        return
    assert parse(str(formula)) == formula, f"{text[:80]!r}... printed as {str(formula)!r} parses differently"
    rho = attempt("stl_extremes", lambda: robustness(formula, _TRACE, _REGIONS, dt=0.1))
    if rho is not None:
        assert not math.isnan(rho), f"robustness of {str(formula)!r} is NaN"

    def online() -> float:
        monitor = OnlineMonitor(formula, _REGIONS, 0.1)
        for k in range(len(_TRACE["O1"])):
            value = monitor.update({name: xy[k] for name, xy in _TRACE.items()})
        return value

    value = attempt("stl_extremes", online)
    if value is not None and rho is not None:
        assert value == pytest.approx(rho, abs=1e-9), f"{str(formula)!r}: online {value} != offline {rho}"
    scenario = attempt("stl_extremes", lambda: scenario_from_dict(S.DICTS["corridor"] | {"task": text}))
    if scenario is not None:
        fly_scenario(scenario)


# ------------------------------------------------------------------------------------ plan files, bytes

# every kind of plan file the package reads: spatially robust (the bench's and the robustness benchmark's),
# impact-robust (funnels), 0.2's, and tether plans; key -> (kind, scenario or station, text)
PLAN_FILES: dict[str, tuple[str, str, str]] = {}
for folder, kind in (("plans/bench", "impact"), ("plans/robustness", "impact"), ("plans/ir", "impact"),
                     ("plans_0.2", "impact"), ("plans/tether", "tether")):
    for path in sorted((DATA / folder).glob("*.json")):
        PLAN_FILES[f"{folder}/{path.name}"] = (kind, path.stem.split("__")[0], path.read_text())
_WORLDS: dict[str, Any] = {}


def _world(kind: str, name: str) -> Any:
    if (kind, name) not in _WORLDS:
        _WORLDS[kind, name] = load_station(name) if kind == "tether" else load_scenario(name)
    return _WORLDS[kind, name]


def plan_bytes(args: tuple[str, bytes]) -> None:
    key, data = args
    kind, name = PLAN_FILES[key][:2]
    path = _fresh(".json")
    path.write_bytes(data)
    world = _world(kind, name)
    tether = attempt("plan_bytes", lambda: is_tether_plan_file(path))  # how `run --plan` picks the reader
    assert tether in (None, True, False)
    if kind == "tether":
        from planners.tether.expert import TetherExpert

        def load_tether() -> TetherPlan:
            plan = TetherPlan.load(path)
            TetherExpert(world, plan=plan)  # checks the plan against its station
            return plan

        plan = attempt("plan_bytes", load_tether)
        if plan is not None:
            assert all(math.isfinite(v) for p in plan.pulls for v in (*p.start_m, *p.end_m))
        return

    def load() -> Plan:
        plan = Plan.load(path)
        plan.check(world, tol=1e-5)
        return plan

    plan = attempt("plan_bytes", load)
    if plan is not None:
        t = np.linspace(0.0, world.tf_s, 51)
        for body in plan.bodies:
            assert_finite(plan.position(body, t), f"{body} position")
            assert_finite(plan.velocity(body, t), f"{body} velocity")


# ------------------------------------------------------------------------------------ model folders, zips

MODELS = {name: DATA / "models" / name for name in ("ppo_corridor", "bc_throw_and_catch_exp")}
_MODEL_BYTES = {name: (folder / "model.zip").read_bytes() for name, folder in MODELS.items()}
_MEMBERS = {name: zipfile.ZipFile(io.BytesIO(data)).namelist() for name, data in _MODEL_BYTES.items()}
# local file header: flags +6, method +8, crc +14, compressed size +18, size +22, name length +26, extra +28;
# central directory record: flags +8, method +10, crc +16, compressed +20, size +24, name length +28, extra +30,
# comment +32, local header offset +42
LOCAL_FIELDS = {"flags": (6, "H"), "method": (8, "H"), "crc": (14, "I"), "compressed": (18, "I"), "size": (22, "I"),
                "name_len": (26, "H"), "extra_len": (28, "H")}
CENTRAL_FIELDS = {"flags": (8, "H"), "method": (10, "H"), "crc": (16, "I"), "compressed": (20, "I"),
                  "size": (24, "I"), "name_len": (28, "H"), "extra_len": (30, "H"), "comment_len": (32, "H"),
                  "offset": (42, "I")}
FIELD_VALUES = st.one_of(st.sampled_from([0, 1, 8, 9, 12, 14, 93, 98, 99, 0x41, 0x800, 0xFFFF, 2 ** 31, 2 ** 32 - 1,
                                          2 ** 30]), st.integers(0, 2 ** 16 - 1))


def _records(raw: bytes, signature: bytes) -> list[int]:
    out, at = [], raw.find(signature)
    while at >= 0:
        out.append(at)
        at = raw.find(signature, at + 4)
    return out


@st.composite
def header_edit(draw, raw: bytes) -> bytes:
    """One field of one member's local header or central directory record set to an edge value."""
    data = bytearray(raw)
    central = draw(st.booleans())
    records = _records(raw, b"PK\x01\x02" if central else b"PK\x03\x04")
    at = draw(st.sampled_from(records))
    field, (offset, fmt) = draw(st.sampled_from(sorted((CENTRAL_FIELDS if central else LOCAL_FIELDS).items())))
    value = draw(FIELD_VALUES) % (2 ** (16 if fmt == "H" else 32))
    struct.pack_into("<" + fmt, data, at + offset, value)
    return bytes(data)


@st.composite
def rebuilt_zip(draw, name: str) -> bytes:
    """The archive rebuilt with member-level changes: one dropped, duplicated, renamed, recompressed, its data
    JSON mutated, a junk or bomb member added, or its 'data' replaced by a bomb."""
    source = zipfile.ZipFile(io.BytesIO(_MODEL_BYTES[name]))
    members = {m: source.read(m) for m in source.namelist()}
    edit = draw(st.sampled_from(["drop", "duplicate", "rename", "recompress", "data_tree", "junk", "bomb"]))
    target = draw(st.sampled_from(sorted(members)))
    compression = zipfile.ZIP_DEFLATED
    extra: list[tuple[str, bytes]] = []
    if edit == "drop":
        del members[target]
    elif edit == "duplicate":
        extra.append((target, members[target][: draw(st.integers(0, 64))]))
    elif edit == "rename":
        members[draw(st.sampled_from(["../data", "/data", "data/", "DATA", "data\x00x", "d" * 300, "policy.pth.bak",
                                      "é"]))] = members.pop(target)
    elif edit == "recompress":
        compression = draw(st.sampled_from([zipfile.ZIP_STORED, zipfile.ZIP_BZIP2, zipfile.ZIP_LZMA]))
    elif edit == "data_tree" and "data" in members:
        try:
            tree = json.loads(members["data"])
        except ValueError:
            tree = {}
        members["data"] = json.dumps(draw(S.mutated_tree(tree)), allow_nan=True).encode()
    elif edit == "junk":
        extra.append((draw(st.text(min_size=1, max_size=20)), draw(st.binary(max_size=200))))
    else:  # a member that inflates far beyond its compressed size (200 MB at most: the test's own memory)
        size = draw(st.sampled_from([10 ** 6, 5 * 10 ** 7, 2 * 10 ** 8]))
        members[draw(st.sampled_from(["data", target]))] = b"\x00" * size
    out = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # zipfile's "Duplicate name"
        with zipfile.ZipFile(out, "w", compression=compression) as z:
            for member, data in [*members.items(), *extra]:
                try:
                    z.writestr(member, data)
                except (ValueError, UnicodeEncodeError, IndexError):
                    pass  # zipfile refuses the name ("/" normalises to "", an IndexError in writestr)
    return out.getvalue()


@st.composite
def binary_edit(draw, raw: bytes) -> bytes:
    data = bytearray(raw)
    for _ in range(draw(st.integers(1, 4))):
        pos = draw(st.integers(0, len(data) - 1))
        edit = draw(st.sampled_from(["flip", "delete", "insert", "truncate"]))
        if edit == "flip":
            data[pos] = draw(st.integers(0, 255))
        elif edit == "delete":
            del data[pos:pos + draw(st.integers(1, 400))]
        elif edit == "insert":
            data[pos:pos] = draw(st.binary(min_size=1, max_size=16))
        else:
            del data[pos:]
        if not data:
            break
    return bytes(data)


SIDECARS = ("train.json", "vecnormalize.json")


@st.composite
def model_folders(draw) -> tuple[str, str, dict[str, Any]]:
    """(base folder, kind of edit, files): ``files`` maps a file name to its bytes, None (removed) or a kind of
    path ("folder", "fifo", "loop", "dangling") for model.zip."""
    name = draw(st.sampled_from(sorted(MODELS)))
    raw = _MODEL_BYTES[name]
    kind = draw(st.sampled_from(["header", "header", "rebuild", "rebuild", "bytes", "sidecar", "path"]))
    files: dict[str, Any] = {}
    if kind == "header":
        files["model.zip"] = draw(header_edit(raw))
    elif kind == "rebuild":
        files["model.zip"] = draw(rebuilt_zip(name))
    elif kind == "bytes":
        files["model.zip"] = draw(binary_edit(raw))
    elif kind == "sidecar":
        sidecar = draw(st.sampled_from(SIDECARS))
        text = (MODELS[name] / sidecar).read_text()
        files[sidecar] = draw(st.one_of(
            st.none(), S.mutated_bytes(text),
            S.mutated_tree(json.loads(text)).map(lambda t: json.dumps(t, allow_nan=True).encode())))
    else:
        files["model.zip"] = draw(st.sampled_from(["folder", "fifo", "loop", "dangling", b""]))
    return name, kind, files


def _lay_out(name: str, files: dict[str, Any]) -> Path:
    folder = _fresh()
    shutil.copytree(MODELS[name], folder)
    for file, content in files.items():
        path = folder / file
        path.unlink()
        if content is None:
            continue
        if isinstance(content, bytes):
            path.write_bytes(content)
        elif content == "folder":
            path.mkdir()
        elif content == "fifo":
            os.mkfifo(path)
        elif content == "loop":
            os.symlink(folder / "other.zip", path)
            os.symlink(path, folder / "other.zip")
        else:
            os.symlink(folder / "gone.zip", path)
    return folder


def model_folder(args: tuple[str, str, dict[str, Any]]) -> None:
    from impact_env.controllers import make_controller
    from impact_env.envs import TransportEnv

    name, _, files = args
    folder = _lay_out(name, files)
    scenario = _world("impact", "corridor" if name == "ppo_corridor" else "throw_and_catch_exp")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the loud warning of a folder without its statistics
            controller = attempt("model_folder", lambda: make_controller(str(folder / "model.zip"), scenario))
            if controller is None:
                return
            with cpu_deadline():
                env = TransportEnv(scenario)
                obs, info = env.reset(seed=0)
                controller.reset(env, 0)
                for _ in range(3):
                    action = np.asarray(controller.act(obs, info), dtype=float)
                    assert action.shape == env.action_space.shape and np.all(np.isfinite(action)), action
                    assert np.all(np.abs(action) <= 1.0 + 1e-6), action
                    obs, _, _, _, info = env.step(action.astype(np.float32))
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ------------------------------------------------------------------------------------ output paths

_PLACES = _TMP / "places"


def _places() -> Path:
    """A folder of every kind of thing a path can meet: a file, a folder, a FIFO, a link loop, a dangling link."""
    if not _PLACES.exists():
        _PLACES.mkdir()
        (_PLACES / "file.json").write_text("{}")
        (_PLACES / "folder").mkdir()
        os.mkfifo(_PLACES / "fifo")
        os.symlink(_PLACES / "loop_b", _PLACES / "loop_a")
        os.symlink(_PLACES / "loop_a", _PLACES / "loop_b")
        os.symlink(_PLACES / "nowhere" / "x.json", _PLACES / "dangling")
        os.symlink(_PLACES / "folder", _PLACES / "link_to_folder")
    return _PLACES


# inside the fixtures' folder, or system paths where nothing can be written (no path here reaches a real folder
# outside the test's own: a random tail has no "/" and no "..")
BASES = ["file.json", "folder", "fifo", "loop_a", "dangling", "link_to_folder", "new", ".", "/dev/full", "/dev/null",
         "/proc/self/status", "/proc", "/proc/impact_env", "/sys/kernel"]
TAILS = ["", "/", "/x.json", "/sub/x.json", "/.", "/..", "/" + "n" * 300 + ".json", "/a\x00b.json", "/\udcff.json",
         "/é ü.png", "/ .json", "/.hidden"]


@st.composite
def output_paths(draw) -> tuple[str, str, str]:
    """(what checks it, the path, a short result text): the file and folder checks with the write they promise,
    or a command (``show --plot``, ``run --json``, ``run --out``) given the path."""
    base = draw(st.sampled_from(BASES))
    tail = draw(st.one_of(st.sampled_from(TAILS),
                          st.text(max_size=12).filter(lambda t: "/" not in t and ".." not in t).map(lambda t: "/" + t)))
    path = base + tail if base.startswith("/") else f"{_places()}/{base}{tail}"
    if draw(st.integers(0, 30)) == 0:
        path = ""  # the empty path
    user = draw(st.sampled_from(["file", "file", "folder", "folder", "show --plot", "run --json", "run --out"]))
    return user, path, draw(st.text(max_size=40))


def output_path(args: tuple[str, str, str]) -> None:
    user, path, text = args
    if user == "file":
        checked = attempt("output_path", lambda: check_output_file(path, "--json"))
        if checked is not None:  # the promise of the check: the write that follows works, whole
            write_atomic(checked, text)
            assert checked.read_bytes() == text.encode("utf-8")
            checked.unlink()
        return
    if user == "folder":
        checked = attempt("output_path", lambda: check_output_folder(path, "--out"))
        if checked is not None:
            write_atomic(checked / "summary.json", text)
            assert (checked / "summary.json").read_bytes() == text.encode("utf-8")
            (checked / "summary.json").unlink()
        return
    from impact_env.cli import main
    from impact_env.figures import png_path  # matplotlib: imported when the test runs

    argv = {"show --plot": ["show", "corridor", "--plot", path],
            "run --json": ["run", "corridor", "--controller", "zero", "--episodes", "1", "--quiet", "--json", path],
            "run --out": ["run", "corridor", "--controller", "zero", "--episodes", "1", "--quiet", "--out", path]}[user]
    err = io.StringIO()
    here = os.getcwd()
    os.chdir(_places())  # a relative default (show's <name>.png) lands among the fixtures
    try:
        with cpu_deadline(), contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse: a path it cannot take as an argument
                code = exc.code
    finally:
        os.chdir(here)
    counts = COUNTS.setdefault("output_path", Counter())
    if code == 0:
        counts["worked"] += 1
        written = {"show --plot": png_path(path), "run --json": Path(path),  # a figure without suffix: PATH.png
                   "run --out": Path(path) / "summary.json"}[user]
        assert written.is_file() and written.stat().st_size > 0, f"{argv}: exit 0 but {written} is not written"
        return
    counts["rejected"] += 1
    message = err.getvalue()
    assert code == 2 and "error:" in message and "Traceback" not in message, (argv, code, message)
    if user.startswith("run"):  # refused before the episode: nothing was flown, nothing was lost
        assert "episode 1/1" not in message


# ------------------------------------------------------------------------------------ the fuzzers

FUZZERS: dict[str, tuple[st.SearchStrategy, Callable[[Any], None]]] = {
    "stl_extremes": (S.stl_extreme_texts(), stl_extremes),
    "plan_bytes": (st.sampled_from(sorted(PLAN_FILES)).flatmap(
        lambda k: st.tuples(st.just(k), S.mutated_bytes(PLAN_FILES[k][2]))), plan_bytes),
    "model_folder": (model_folders(), model_folder),
    "output_path": (output_paths(), output_path),
}


@pytest.mark.parametrize("name", sorted(FUZZERS))
def test_files_fuzz(name):
    fuzz_fixed(name, *FUZZERS[name], DEFAULT_EXAMPLES[name])


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FUZZERS))
def test_files_fuzz_long(name):
    fuzz_for_budget(name, *FUZZERS[name], ROUND[name])


def test_the_output_places_are_what_they_say():
    """The fuzzer's fixtures: a test that they are the kinds of path the issue lists, and that the checks
    refuse the ones that cannot take a result."""
    places = _places()
    for name in ("folder", "fifo", "loop_a"):
        with pytest.raises(OutputPathError):
            check_output_file(places / name)
    with pytest.raises(OutputPathError, match="/dev/full is a character device"):
        check_output_file("/dev/full", "--json")
    with pytest.raises(OutputPathError, match="cannot create"):
        check_output_file("/proc/impact_env.json")
    assert check_output_file(places / "dangling") == places / "dangling"  # a link to a file yet to be written
