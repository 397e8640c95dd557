"""Output paths checked before work and written atomically (issue 24): the checks of
:mod:`impact_env.results_store` on each kind of path, and every writer of the package going through
``atomic_path`` (a failure mid-write leaves the old file whole and no temporary file behind)."""

from __future__ import annotations

import errno
import json
import os
from pathlib import Path

import numpy as np
import pytest

from impact_env.errors import OutputPathError
from impact_env.results_store import atomic_path, check_output_file, check_output_folder, write_atomic
from tests.paths import DATA


@pytest.fixture
def paths(tmp_path):
    (tmp_path / "file.txt").write_text("x")
    (tmp_path / "folder").mkdir()
    os.mkfifo(tmp_path / "fifo")
    os.symlink(tmp_path / "loop_b", tmp_path / "loop_a")
    os.symlink(tmp_path / "loop_a", tmp_path / "loop_b")
    os.symlink(tmp_path / "missing.json", tmp_path / "dangling.json")
    return tmp_path


@pytest.mark.parametrize("name, message", [
    ("folder", "--json {p} is a folder, not a file"),
    ("fifo", "--json {p} is a FIFO (named pipe), not a file"),
    ("loop_a", "--json {p} is a loop of symbolic links"),
    ("file.txt/out.json", "--json {p}: a part of the path is a file, not a folder"),
])
def test_file_checks_name_the_path_and_the_reason(paths, name, message):
    path = paths / name
    with pytest.raises(OutputPathError) as info:
        check_output_file(path, "--json")
    assert str(info.value).startswith(message.format(p=path))


def test_file_checks_accept_new_files_replaced_files_and_dangling_links(paths):
    assert check_output_file(paths / "new" / "deep" / "out.json", "--json") == paths / "new" / "deep" / "out.json"
    assert (paths / "new" / "deep").is_dir()  # the folder is made now, so the check holds later
    check_output_file(paths / "file.txt")
    check_output_file(paths / "dangling.json")
    assert not list(paths.glob(".write-check-*")) and not list((paths / "new" / "deep").iterdir())


def test_a_name_too_long_is_refused_by_the_check_even_in_a_folder_not_made_yet(tmp_path):
    """The file system reports a name too long only inside a folder that exists: the check looks again once it
    has made the folder, so that what it passes, the write takes (a fuzzer found the gap)."""
    too_long = tmp_path / "new" / ("n" * 300 + ".json")
    with pytest.raises(OutputPathError, match="cannot be checked: File name too long"):
        check_output_file(too_long, "--json")
    with pytest.raises(OutputPathError, match="cannot be checked: File name too long"):
        check_output_file(too_long, "--json")  # the same answer once the folder is there


def test_the_longest_name_the_file_system_takes_is_written(tmp_path):
    """The temporary file beside it has a bounded name, so it never is the one too long."""
    longest = tmp_path / ("n" * (os.pathconf(tmp_path, "PC_NAME_MAX") - 5) + ".json")
    write_atomic(check_output_file(longest), "data")
    assert longest.read_text() == "data" and [p.name for p in tmp_path.iterdir()] == [longest.name]


@pytest.mark.parametrize("path, message", [("/dev/full", "is a character device, not a file"),
                                           ("/proc/x/out.json", "cannot create the folder"),
                                           ("/proc/out.json", "cannot create files in /proc")])
def test_system_paths(path, message):
    with pytest.raises(OutputPathError, match=message):
        check_output_file(path, "--json")


@pytest.mark.parametrize("name, message", [("file.txt", "is a file, not a folder"),
                                           ("fifo", "is a FIFO (named pipe), not a folder"),
                                           ("loop_a", "is a loop of symbolic links"),
                                           ("file.txt/sub", "a part of the path is a file")])
def test_folder_checks(paths, name, message):
    with pytest.raises(OutputPathError, match=message.replace("(", r"\(").replace(")", r"\)")):
        check_output_folder(paths / name, "--out")
    assert check_output_folder(paths / "folder" / "new", "--out").is_dir()
    with pytest.raises(OutputPathError, match="is a character device, not a folder"):
        check_output_folder("/dev/full", "--out")


def test_atomic_path_never_replaces_something_that_is_not_a_file(paths):
    for name in ("fifo", "folder"):
        with pytest.raises(OutputPathError, match="not a file: not replaced"):
            write_atomic(paths / name, "data")
    assert (paths / "fifo").is_fifo() and (paths / "folder").is_dir()


def test_a_failed_write_keeps_the_old_file_and_names_the_path(tmp_path):
    target = tmp_path / "summary.json"
    target.write_text("old")
    with pytest.raises(OutputPathError, match=f"cannot write {target}: No space left on device"):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert target.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["summary.json"]


def _fail_after_writing(monkeypatch, cls, name):
    original = getattr(cls, name)

    def partial(self, path, *args, **kwargs):
        original(self, path, *args, **kwargs)
        Path(path).write_bytes(Path(path).read_bytes()[:10])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(cls, name, partial)


def test_figures_are_written_atomically(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from impact_env import load_scenario
    from impact_env.transport.plotting import save_scenario_figure

    target = tmp_path / "setup.png"
    target.write_bytes(b"old figure")
    _fail_after_writing(monkeypatch, Figure, "savefig")
    with pytest.raises(OutputPathError, match="cannot write"):
        save_scenario_figure(load_scenario("corridor"), target)
    assert target.read_bytes() == b"old figure" and [p.name for p in tmp_path.iterdir()] == ["setup.png"]


def test_plans_summaries_and_videos_are_written_atomically(tmp_path, monkeypatch):
    from impact_env import cli_options
    from impact_env.rollout import write_video
    from planners.plan import Plan

    plan = Plan.load(DATA / "plans" / "bench" / "corridor.json")
    written = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (written.append((Path(a), Path(b))), real(a, b))[1])
    plan.save(tmp_path / "plan.json")
    cli_options.save_summary(str(tmp_path / "summary.json"), {"a": 1})
    write_video([np.zeros((8, 8, 3), np.uint8)] * 3, str(tmp_path / "run.mp4"), fps=10)
    assert [b.name for _, b in written] == ["plan.json", "summary.json", "run.mp4"]
    assert all(a.parent == b.parent and a.name.startswith(f".{b.stem}.tmp-") and a.suffix == b.suffix
               for a, b in written)
    assert json.loads((tmp_path / "summary.json").read_text()) == {"a": 1}
    assert (tmp_path / "run.mp4").stat().st_size > 0


# found by tests/fuzz/test_files_fuzz.py (output_path)
def test_a_plot_whose_suffix_no_writer_takes_is_refused_before_work(tmp_path, capsys):
    from impact_env.cli import main

    assert main(["show", "corridor", "--plot", str(tmp_path / "setup.json")]) == 2
    err = capsys.readouterr().err
    assert ".json is not an image format matplotlib writes" in err and ".png" in err and ".pdf" in err
    assert not list(tmp_path.iterdir())
    assert main(["show", "corridor", "--plot", str(tmp_path / "setup.svg")]) == 0  # a format it writes
    assert (tmp_path / "setup.svg").read_bytes().lstrip().startswith(b"<?xml")


@pytest.mark.parametrize("option", ["--plot", "--out"])
@pytest.mark.parametrize("path, message", [("", "is an empty path"), ("  ", "is an empty path"),
                                           ("a\0b.png", "contains a NUL byte")])
def test_empty_and_nul_paths_are_usage_errors(tmp_path, monkeypatch, capsys, option, path, message):
    from impact_env.cli import main

    monkeypatch.chdir(tmp_path)  # 0.3.0 wrote corridor.png here for --plot ""
    with pytest.raises(SystemExit) as info:
        main(["show", "corridor", option, path])
    assert info.value.code == 2 and message in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_a_nul_byte_is_an_output_path_error(tmp_path):
    with pytest.raises(OutputPathError, match="contains a NUL byte"):
        check_output_file(str(tmp_path / "a\0b.json"), "--json")
    with pytest.raises(OutputPathError, match="contains a NUL byte"):
        check_output_folder(str(tmp_path / "a\0b"), "--out")
