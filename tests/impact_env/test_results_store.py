"""impact_env.results_store: atomic writes, one JSONL file of cells, resume, and what a damaged file says.

The kill test writes cells through the store in a subprocess that stops in the middle of writing the file's
new version (half of it on disk) and is killed there with SIGKILL; the file must still hold every cell put
before, and a second run must put only the cells that are missing."""

from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap

import pytest

from impact_env.errors import ResultsFileError
from impact_env.results_store import CellStore, atomic_path, write_atomic
from tests.paths import ROOT


def by_name(cell: dict) -> tuple:
    return cell["scenario"], cell["level"]


def cell(name: str, level: float, rho: float = 0.1) -> dict:
    return {"scenario": name, "level": level, "episodes": [{"seed": 0, "robustness": rho}]}


def test_write_atomic_writes_the_bytes_with_the_usual_permissions(tmp_path):
    path = write_atomic(tmp_path / "new" / "table.md", "| a |\n")
    assert path.read_text() == "| a |\n"
    plain = tmp_path / "plain.md"
    plain.write_text("x")
    assert stat.S_IMODE(path.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
    write_atomic(path, b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01" and sorted(p.name for p in path.parent.iterdir()) == ["table.md"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary_one(tmp_path):
    path = write_atomic(tmp_path / "bench.png", "old")
    with pytest.raises(RuntimeError, match="figure failed"), atomic_path(path) as tmp:
        assert tmp.parent == path.parent and tmp.suffix == ".png" and tmp.name.startswith(".bench.tmp-")
        tmp.write_text("half a fig")
        raise RuntimeError("figure failed")
    assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["bench.png"]


def test_cells_are_put_got_replaced_in_place_and_read_back_to_the_last_bit(tmp_path):
    path = tmp_path / "cells.jsonl"
    store = CellStore(path, by_name)
    assert len(store) == 0 and store.get(("corridor", 0.1)) is None and not path.exists()
    store.put(cell("corridor", 0.1, 0.1 + 0.2))
    store.put(cell("relay", 0.3))
    store.put(cell("corridor", 0.1, -1 / 3))  # the same key: replaced, where it was
    assert path.read_text() == (json.dumps(cell("corridor", 0.1, -1 / 3)) + "\n" + json.dumps(cell("relay", 0.3))
                                + "\n")
    again = CellStore(path, by_name)
    assert again.keys() == [("corridor", 0.1), ("relay", 0.3)] and ("relay", 0.3) in again
    assert again.get(("corridor", 0.1))["episodes"][0]["robustness"] == -1 / 3
    assert [c["scenario"] for c in again] == ["corridor", "relay"]


def test_lines_already_in_the_file_are_rewritten_byte_for_byte(tmp_path):
    path = tmp_path / "cells.jsonl"
    path.write_text('{"scenario":"corridor","level":0.1,   "x": 1.10}\n')  # not json.dumps' spelling
    store = CellStore(path, by_name)
    store.put(cell("relay", 0.3))
    assert path.read_text().splitlines()[0] == '{"scenario":"corridor","level":0.1,   "x": 1.10}'


def test_put_many_replaces_and_appends_in_one_write(tmp_path, monkeypatch):
    path = tmp_path / "cells.jsonl"
    store = CellStore(path, by_name)
    store.put(cell("corridor", 0.1))
    store.put(cell("relay", 0.3))
    writes = []
    monkeypatch.setattr("impact_env.results_store.write_atomic", lambda p, text: writes.append(text))
    store.put_many([cell("relay", 0.3, 0.7), cell("two_objects", 0.2)])
    store.put_many([])
    assert writes == ["".join(json.dumps(c) + "\n" for c in (cell("corridor", 0.1), cell("relay", 0.3, 0.7),
                                                            cell("two_objects", 0.2)))]


def test_a_cut_last_line_is_reported_with_its_number_not_dropped(tmp_path):
    path = tmp_path / "cells.jsonl"
    lines = [json.dumps(cell("corridor", 0.1)), json.dumps(cell("relay", 0.3))]
    path.write_text(lines[0] + "\n" + lines[1][:25])  # an older writer appending in place, killed
    with pytest.raises(ResultsFileError, match=r"cells.jsonl, line 2 \(the last line, with no newline at its "
                                               r"end\) is not a complete JSON object .*sed -i '2d'"):
        CellStore(path, by_name).get(("corridor", 0.1))
    path.write_text(lines[0] + "\n" + lines[1][:25] + "\n" + lines[1] + "\n")
    with pytest.raises(ResultsFileError, match=r"line 2 is not a complete JSON object"):
        len(CellStore(path, by_name))
    with pytest.raises(ResultsFileError, match="line 2"):  # put reads the file first: it never drops the line
        CellStore(path, by_name).put(cell("ping_pong_stop", 0.0))
    assert path.read_text().count("\n") == 3


@pytest.mark.parametrize("text, message", [
    ("[1, 2]\n", r"line 1 is a JSON list, not an object"),
    ('{"scenario": "corridor"}\n', r"line 1: the cell lacks a field of its key .*KeyError: 'level'"),
    ('{"scenario": "a", "level": 1}\n\n{"scenario": "a", "level": 1}\n', r"line 3 repeats the cell \('a', 1\)"),
])
def test_lines_that_are_not_cells_are_reported(tmp_path, text, message):
    path = tmp_path / "cells.jsonl"
    path.write_text(text)
    with pytest.raises(ResultsFileError, match=message):
        CellStore(path, by_name).cells()


def test_a_file_that_is_not_text_is_reported(tmp_path):
    path = tmp_path / "cells.jsonl"
    path.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ResultsFileError, match="is not UTF-8 text"):
        CellStore(path, by_name).cells()


WRITER = textwrap.dedent("""
    import pathlib, sys, time
    from impact_env.results_store import CellStore

    path, stop_after = pathlib.Path(sys.argv[1]), int(sys.argv[2])
    store = CellStore(path, lambda c: c["k"])
    written = 0
    real = pathlib.Path.write_bytes

    def write_bytes(self, data):  # the write of the file's new version after `stop_after` puts: half, then wait
        if written == stop_after:
            with open(self, "wb") as f:
                f.write(data[: len(data) // 2])
            print("mid-write", flush=True)
            time.sleep(600)
        return real(self, data)

    pathlib.Path.write_bytes = write_bytes
    for k in range(10):
        if store.get(k) is None:  # resume: the cells done are skipped
            store.put({"k": k, "episodes": list(range(20000 + k))})
            written += 1
            print(f"put {k}", flush=True)
""")


def test_a_kill_in_the_middle_of_a_write_loses_nothing_and_the_rerun_resumes(tmp_path):
    path = tmp_path / "cells.jsonl"
    child = subprocess.Popen([sys.executable, "-c", WRITER, str(path), "4"], stdout=subprocess.PIPE, text=True,
                             cwd=ROOT)
    lines = []
    try:
        for line in child.stdout:
            lines.append(line.strip())
            if line.strip() == "mid-write":
                child.send_signal(signal.SIGKILL)
                break
    finally:
        child.kill()
        child.wait(timeout=60)
    assert lines == ["put 0", "put 1", "put 2", "put 3", "mid-write"]
    assert child.returncode == -signal.SIGKILL
    stale = [p for p in tmp_path.iterdir() if p != path]
    assert len(stale) == 1 and stale[0].name.startswith(".cells.tmp-")  # the half-written new version
    assert stale[0].stat().st_size < path.stat().st_size * 5 // 4
    store = CellStore(path, lambda c: c["k"])
    assert store.keys() == [0, 1, 2, 3] and all(len(store.get(k)["episodes"]) == 20000 + k for k in range(4))

    rerun = subprocess.run([sys.executable, "-c", WRITER, str(path), "-1"], capture_output=True, text=True,
                           cwd=ROOT, timeout=120, check=True)
    assert rerun.stdout.split("\n")[:-1] == [f"put {k}" for k in range(4, 10)]
    store = CellStore(path, lambda c: c["k"])
    assert store.keys() == list(range(10)) and len(store.get(9)["episodes"]) == 20009


def test_a_kill_at_any_moment_leaves_a_whole_file(tmp_path):
    """Killed at arbitrary moments (no hook): each time the file reads back as the cells put, in order."""
    path = tmp_path / "cells.jsonl"
    for delay in (0.3, 0.5, 0.8):
        child = subprocess.Popen([sys.executable, "-c", WRITER, str(path), "-1"], stdout=subprocess.PIPE,
                                 text=True, cwd=ROOT)
        try:
            child.communicate(timeout=delay)
        except subprocess.TimeoutExpired:
            os.kill(child.pid, signal.SIGKILL)
            child.communicate()
        keys = CellStore(path, lambda c: c["k"]).keys() if path.exists() else []
        assert keys == list(range(len(keys)))
    subprocess.run([sys.executable, "-c", WRITER, str(path), "-1"], capture_output=True, cwd=ROOT, timeout=120,
                   check=True)
    assert CellStore(path, lambda c: c["k"]).keys() == list(range(10))
