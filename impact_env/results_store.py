"""Results files written atomically: one JSONL file per benchmark (a cell per line), resumable.

A benchmark keeps its cells (one condition's episodes and what they measured) in one ``cells.jsonl``, one
JSON object per line, identified by a key the benchmark chooses (scenario, stack, condition, ...).
:class:`CellStore` reads them back so that a rerun skips the cells already done, and :meth:`CellStore.put`
replaces or appends a cell by rewriting the whole file through :func:`write_atomic`: a temporary file in the
same folder, then ``os.replace``. A kill at any moment leaves the old file or the new one, never a part of
one (a stale ``.<name>.tmp-*`` may be left beside it; nothing reads it). A line that is not a complete JSON
object (the last line of a file an older writer was appending to when it was killed) is reported as a
:class:`~impact_env.errors.ResultsFileError` naming the file and line, never dropped silently. One writer
per file at a time. The tables and CSV files the benchmarks print are written with :func:`write_atomic` too.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import stat
import uuid
from collections.abc import Callable, Hashable, Iterator
from pathlib import Path
from typing import Any

from impact_env.errors import OutputPathError, ResultsFileError

__all__ = ["CellStore", "atomic_path", "check_output_file", "check_output_folder", "write_atomic"]


def _named(path: Path, option: str | None) -> str:
    return f"{option} {path}" if option else str(path)


def _kind(mode: int) -> str:
    return ("a folder" if stat.S_ISDIR(mode) else "a character device" if stat.S_ISCHR(mode) else
            "a block device" if stat.S_ISBLK(mode) else "a FIFO (named pipe)" if stat.S_ISFIFO(mode) else
            "a socket" if stat.S_ISSOCK(mode) else "not a regular file")


def _stat(path: Path, named: str) -> os.stat_result | None:
    """``path``'s status through its links; None if nothing is there (or a link points nowhere)."""
    try:
        return path.stat()
    except FileNotFoundError:
        return None
    except ValueError:  # a NUL byte: no file system takes it
        raise OutputPathError(f"{named} contains a NUL byte, which no path can") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise OutputPathError(f"{named} is a loop of symbolic links") from None
        if exc.errno == errno.ENOTDIR:
            raise OutputPathError(f"{named}: a part of the path is a file, not a folder") from None
        raise OutputPathError(f"{named} cannot be checked: {exc.strerror or exc}") from None


def _probe(folder: Path, named: str) -> None:
    """Create and remove a file in ``folder``, as :func:`atomic_path` will: permissions alone do not tell (root
    passes every permission check, yet cannot create a file in ``/proc``)."""
    probe = folder / f".write-check-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    except OSError as exc:
        raise OutputPathError(f"{named}: cannot create files in {folder}: {exc.strerror or exc}") from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:
        pass


def _make_folder(folder: Path, named: str) -> None:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise OutputPathError(f"{named}: {folder} exists and is not a folder") from None
    except OSError as exc:
        if exc.errno == errno.ENOTDIR:
            raise OutputPathError(f"{named}: a part of {folder} is a file, not a folder") from None
        raise OutputPathError(f"{named}: cannot create the folder {folder}: {exc.strerror or exc}") from None


def check_output_file(path: str | os.PathLike, option: str | None = None) -> Path:
    """Check, before any work, that a result can be written to the file ``path`` (``option`` names the command
    line option that gave it, for the message): nothing is there, or a regular file that will be replaced; its
    folder exists or can be created (it is created now), and a file can be created in it. Anything else is an
    :class:`~impact_env.errors.OutputPathError` naming the path and the reason: a folder, ``/dev/full`` (a
    device: it would be replaced, or written into and fail), a FIFO, a symbolic-link loop, a folder under
    ``/proc``. Returns the path."""
    path = Path(path)
    named = _named(path, option)
    if not path.name or path.name in (".", ".."):
        raise OutputPathError(f"{named} names a folder, not a file")
    status = _stat(path, named)
    if status is not None and not stat.S_ISREG(status.st_mode):
        hint = " (a file path is expected here; --out takes a folder)" if stat.S_ISDIR(status.st_mode) else ""
        raise OutputPathError(f"{named} is {_kind(status.st_mode)}, not a file{hint}")
    _make_folder(path.parent, named)
    if status is None:  # again, now that the folder exists: a name too long only shows inside an existing folder
        status = _stat(path, named)
        if status is not None and not stat.S_ISREG(status.st_mode):  # created meanwhile by another writer
            raise OutputPathError(f"{named} is {_kind(status.st_mode)}, not a file")
    _probe(path.parent, named)
    return path


def check_output_folder(path: str | os.PathLike, option: str | None = None) -> Path:
    """Check, before any work, that results can be written into the folder ``path``: it is a folder or can be
    created (it is created now), and a file can be created in it; else an
    :class:`~impact_env.errors.OutputPathError` naming it and the reason. Returns the path."""
    path = Path(path)
    named = _named(path, option)
    status = _stat(path, named)
    if status is not None and not stat.S_ISDIR(status.st_mode):
        raise OutputPathError(f"{named} is {_kind(status.st_mode) if not stat.S_ISREG(status.st_mode) else 'a file'}"
                              ", not a folder")
    _make_folder(path, named)
    _probe(path, named)
    return path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """A temporary path beside ``path`` (same folder, same suffix) for the block to write; when the block ends
    without an error the file is flushed to disk and renamed over ``path`` (``os.replace``: atomic on one file
    system), otherwise removed. The folder is created if missing. A path that is something else than a regular
    file (a folder, a device) is refused, and any failure of the file system is an
    :class:`~impact_env.errors.OutputPathError` naming the path. For writers that want a path, not a string
    (``Plan.save``, ``csv``, ``Figure.savefig``, which reads the format from the suffix)::

        with atomic_path(out / "bench.png") as tmp:
            fig.savefig(tmp)
    """
    path = Path(path)
    status = _stat(path, str(path))
    if status is not None and not stat.S_ISREG(status.st_mode):  # never rename over /dev/full or a folder
        raise OutputPathError(f"{path} is {_kind(status.st_mode)}, not a file: not replaced")
    _make_folder(path.parent, str(path))
    # the stem is cut so that the temporary name is never longer than a name the file system took for ``path``
    tmp = path.with_name(f".{path.stem[:64]}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}{path.suffix[:32]}")
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OutputPathError):
            raise
        raise OutputPathError(f"cannot write {path}: {exc.strerror or exc}") from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_folder(path.parent)


def write_atomic(path: str | os.PathLike, data: str | bytes) -> Path:
    """Write ``data`` (text is UTF-8 encoded) to ``path`` through :func:`atomic_path`: a reader, or a kill at
    any moment, sees the old file or the new one, never a part. Returns the path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.encode("utf-8") if isinstance(data, str) else bytes(data))
    return path


def _fsync_folder(folder: Path) -> None:
    """Make the rename itself durable (POSIX); a no-op where folders cannot be opened (Windows)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class CellStore:
    """The cells of one benchmark in one JSONL file, each identified by ``key(cell)``.

    ``path`` need not exist yet (no cells). The file is read once, on first use; every line must be a JSON
    object with the fields ``key`` reads, and no two lines may have the same key (else
    :class:`~impact_env.errors.ResultsFileError`). Cells keep the file's order; a new cell goes at the end. A
    new cell is written as ``json.dumps(cell)`` on one line (read back, it equals the one put, floats to the
    last bit), and the lines of the cells already there are rewritten as they were, byte for byte.
    """

    def __init__(self, path: str | os.PathLike, key: Callable[[dict], Hashable]) -> None:
        self.path = Path(path)
        self.key = key
        self._lines: dict[Hashable, str] | None = None  # key -> the cell's line, without its newline

    def _loaded(self) -> dict[Hashable, str]:
        if self._lines is None:
            self._lines = self._read()
        return self._lines

    def _read(self) -> dict[Hashable, str]:
        lines: dict[Hashable, str] = {}
        if not self.path.exists():
            return lines
        try:
            text = self.path.read_text(encoding="utf-8")
        except UnicodeDecodeError as err:
            raise ResultsFileError(f"{self.path} is not UTF-8 text ({err}): not a cells file") from None
        rows = text.split("\n")
        for number, line in enumerate(rows, start=1):
            if not line.strip():
                continue
            where = f"{self.path}, line {number}"
            try:
                cell = json.loads(line)
            except ValueError as err:
                end = " (the last line, with no newline at its end)" if number == len(rows) else ""
                raise ResultsFileError(
                    f"{where}{end} is not a complete JSON object ({err}): a write was cut short, e.g. an older "
                    f"writer that appended to the file in place was killed. Delete that line (sed -i "
                    f"'{number}d' {self.path}) and rerun: its cell is run again") from None
            if not isinstance(cell, dict):
                raise ResultsFileError(f"{where} is a JSON {type(cell).__name__}, not an object (one cell per "
                                       "line)")
            try:
                key = self.key(cell)
            except (KeyError, TypeError, ValueError) as err:
                raise ResultsFileError(f"{where}: the cell lacks a field of its key or has a malformed one "
                                       f"({type(err).__name__}: {err})") from None
            if key in lines:
                raise ResultsFileError(f"{where} repeats the cell {key!r} of an earlier line: keep one of them")
            lines[key] = line
        return lines

    def get(self, key: Hashable) -> dict | None:
        """The cell with this key (a new dict on every call), or None."""
        line = self._loaded().get(key)
        return None if line is None else json.loads(line)

    def put(self, cell: dict) -> None:
        """Replace the cell with ``cell``'s key (in place) or append it, and rewrite the file atomically."""
        self.put_many([cell])

    def put_many(self, cells: list[dict]) -> None:
        """:meth:`put` of several cells in one atomic rewrite (nothing written when ``cells`` is empty)."""
        if not cells:
            return
        lines = self._loaded()
        for cell in cells:
            line = json.dumps(cell)  # one line: json.dumps escapes every newline inside strings
            lines[self.key(json.loads(line))] = line  # the key a reader of the file will compute
        write_atomic(self.path, "".join(text + "\n" for text in lines.values()))

    def keys(self) -> list[Hashable]:
        """The cells' keys, in the file's order."""
        return list(self._loaded())

    def cells(self) -> list[dict]:
        """Every cell, in the file's order."""
        return [json.loads(line) for line in self._loaded().values()]

    def __iter__(self) -> Iterator[dict]:
        return iter(self.cells())

    def __len__(self) -> int:
        return len(self._loaded())

    def __contains__(self, key: Any) -> bool:
        return key in self._loaded()
