"""Every code block of the README and of the documentation pages (``docs/*.md``) is checked by the suite.

- Each ```python block runs, in a fresh namespace and an empty working folder. A block shown on several pages
  (the README's quick start is also on the site) runs once, under the first place it appears.
- A block that cannot run in a test is not a ```python block: commands are ```bash blocks. A python block that
  must not run here, or only in the slow suite, says so on the line above its fence, with its reason:
  ``<!-- test: skip, why -->`` or ``<!-- test: slow, why -->`` (docs/batched.md skips its compiled example
  and runs its BenchMARL one in the slow suite).
- Every ``impact-env ...`` line of a ```bash block parses with :func:`impact_env.cli.build_parser` (parsed, not
  run).
- What the text names exists: the scripts run as ``python path.py`` or ``python -m module``, the repository
  paths in code spans (``planners/online/mission.py``), the dotted Python names in code spans
  (``planners.expert.Expert``), and the README's links and images.
"""

from __future__ import annotations

import configparser
import glob
import importlib
import importlib.util
import re
import shlex
import sys
import types
from dataclasses import dataclass
from pathlib import Path

import pytest

from tests.paths import ROOT

SOURCES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LANGUAGES = {"python", "bash", "text", "toml", "json"}
FENCE = re.compile(r"^```(\S*)\s*$")
MARK = re.compile(r"^<!-- test: (skip|slow), (\S.*?) -->$")


@dataclass(frozen=True)
class Block:
    path: Path
    line: int  # 1-based line of the opening fence
    language: str
    code: str
    mark: tuple[str, str] | None  # ("skip" | "slow", reason) from the line above the fence

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"


def code_blocks(path: Path) -> list[Block]:
    """The fenced blocks of a Markdown file (fences at the start of a line, as every page writes them)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks, i = [], 0
    while i < len(lines):
        opening = FENCE.match(lines[i])
        if not opening:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].rstrip() == "```"), None)
        assert end is not None, f"{path.relative_to(ROOT)}:{i + 1}: a code block that is never closed"
        mark = MARK.match(lines[i - 1].strip()) if i else None
        blocks.append(Block(path, i + 1, opening.group(1), "\n".join(lines[i + 1:end]) + "\n",
                            (mark.group(1), mark.group(2)) if mark else None))
        i = end + 1
    return blocks


BLOCKS = [block for path in SOURCES for block in code_blocks(path)]


def _python_blocks() -> list:
    seen, params = set(), []
    for block in BLOCKS:
        if block.language != "python" or block.code in seen:
            continue
        seen.add(block.code)
        marks = []
        if block.mark and block.mark[0] == "skip":
            marks.append(pytest.mark.skip(reason=block.mark[1]))
        elif block.mark:
            marks.append(pytest.mark.slow)
        params.append(pytest.param(block, id=block.where, marks=marks))
    return params


@pytest.mark.parametrize("block", _python_blocks())
def test_python_block_runs(block, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    module = types.ModuleType("__docs__")  # a real module, as a reader's script is: dataclasses look it up
    monkeypatch.setitem(sys.modules, module.__name__, module)
    exec(compile(block.code, block.where, "exec"), module.__dict__)


def test_code_blocks_reads_fences_and_marks(tmp_path, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    page = tmp_path / "page.md"
    page.write_text("text\n```bash\nimpact-env scenarios\n```\n<!-- test: slow, trains for an hour -->\n"
                    "```python\nprint(1)\n```\n```\nplain\n```\n", encoding="utf-8")
    blocks = code_blocks(page)
    assert [(b.line, b.language, b.code, b.mark) for b in blocks] == [
        (2, "bash", "impact-env scenarios\n", None), (6, "python", "print(1)\n", ("slow", "trains for an hour")),
        (9, "", "plain\n", None)]
    assert blocks[1].where == "page.md:6"


def test_every_code_block_says_its_language():
    """An unlabelled or mislabelled block (```py, ```Python) would silently escape the checks above."""
    bad = [f"{b.where}: ```{b.language}" for b in BLOCKS if b.language not in LANGUAGES]
    assert not bad, "\n".join(bad)
    assert sum(b.language == "python" for b in BLOCKS) >= 10


def test_marks_sit_on_python_blocks():
    text = "\n".join(p.read_text(encoding="utf-8") for p in SOURCES)
    marked = [b for b in BLOCKS if b.mark]
    assert text.count("<!-- test:") == len(marked), "a '<!-- test: ... -->' mark not right above a fence"
    assert all(b.language == "python" for b in marked), [b.where for b in marked]


def test_readme_has_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert "make demo" in text and "make test" in text
    assert len(text.splitlines()) <= 300


def _command_lines() -> list[tuple[str, list[str]]]:
    out = []
    for block in BLOCKS:
        if block.language != "bash":
            continue
        for k, line in enumerate(block.code.replace("\\\n", " ").splitlines()):
            words = shlex.split(line, comments=True)
            if words and words[0] == "impact-env":
                out.append((f"{block.where} (+{k + 1})", words[1:]))
    return out


def test_command_lines_parse():
    """Every `impact-env ...` line in the README's and the pages' shell blocks is a valid command line."""
    from impact_env.cli import build_parser

    parser = build_parser()
    commands = _command_lines()
    assert len(commands) >= 30 and any(w.startswith("README.md") for w, _ in commands)
    for where, words in commands:
        try:
            args = parser.parse_args(words)
        except SystemExit:
            pytest.fail(f"{where}: impact-env {shlex.join(words)} does not parse")
        assert callable(args.func), where


def _texts() -> list[tuple[Path, str]]:
    return [(p, p.read_text(encoding="utf-8")) for p in SOURCES]


def test_scripts_the_docs_run_exist():
    """`python benchmarks/x.py`, `python -m pkg.mod` and `bash x.sh`, in code blocks and in the prose."""
    missing = []
    for path, text in _texts():
        for m in re.finditer(r"\b(?:python|bash)\s+(-m [\w.]+|[\w./-]+\.(?:py|sh))\b", text):
            target = m.group(1)
            if target.startswith("-m "):
                module = target[3:]
                found = module.split(".")[0] in ("rl_zoo3", "pytest") or importlib.util.find_spec(module)
            else:
                found = (ROOT / target).is_file()
            if not found:
                missing.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert not missing, "\n".join(sorted(set(missing)))


def _code_spans(text: str) -> list[str]:
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return [word.strip("(),;:") for span in re.findall(r"`([^`\n]+)`", text) for word in span.split()]


def test_repository_paths_the_docs_name_exist():
    """A path like `planners/online/mission.py` or `benchmarks/results/robustness/` in a code span is there."""
    missing = []
    for path, text in _texts():
        for word in _code_spans(text):
            if not re.match(r"(impact_env|planners|baselines|benchmarks|tests|scripts|docs|\.ci)/[\w./*-]+$", word):
                continue
            if re.search(r"-v\d+$", word):  # an environment id (impact_env/Corridor-v0) or a dataset id
                continue
            if not glob.glob(str(ROOT / word.split("#")[0])):
                missing.append(f"{path.relative_to(ROOT)}: {word}")
    assert not missing, "\n".join(sorted(set(missing)))


def _resolves(name: str) -> bool:
    parts = name.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            return False
        return True
    return False


def test_python_names_the_docs_use_resolve():
    """`planners.online.side_switch.unflyable_side_switches` imports, and so does every `::: name` of the API
    page (mkdocstrings); entry-point groups (`impact_env.controllers`) are names too."""
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    groups = set(config["options.entry_points"])
    stale = []
    for path, text in _texts():
        for word in _code_spans(text) + re.findall(r"^::: ([\w.]+)", text, flags=re.M):
            if re.fullmatch(r"(impact_env|planners|baselines)(\.\w+)+", word) and word not in groups \
                    and not _resolves(word):
                stale.append(f"{path.relative_to(ROOT)}: {word}")
    assert not stale, "\n".join(sorted(set(stale)))


def test_readme_links_and_images_exist():
    """The README is read on the forge, not through the site's strict build: its relative targets must exist."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)\s]+)\)", text) + re.findall(r'<img src="([^"]+)"', text)
    local = [t for t in targets if not re.match(r"https?://|mailto:|#", t)]
    assert local
    missing = [t for t in local if not (ROOT / t.split("#")[0]).exists()]
    assert not missing, missing


def _walk():
    spec = importlib.util.spec_from_file_location("impact_env_new_user_walk", ROOT / "scripts" / "new_user_walk.py")
    walk = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = walk  # its dataclass looks its module up
    spec.loader.exec_module(walk)
    return walk


def test_the_new_user_walk_runs_the_blocks_the_suite_runs():
    """``make wheel-check`` runs scripts/new_user_walk.py on copies of these pages in the wheel's venv: the same
    blocks, under the same names, with the same marks, as test_python_block_runs above."""
    walk = _walk()
    ours = [(p.values[0].where, p.values[0].code, p.values[0].mark) for p in _python_blocks()]
    theirs = [(b.where, b.code, b.mark) for b in walk.python_blocks(SOURCES, ROOT)]
    assert theirs == ours and len(ours) >= 10


def test_the_new_user_walk_refuses_a_checkout_and_records_a_video(tmp_path, capsys):
    walk = _walk()
    assert walk.main([str(ROOT / "README.md")]) == 1  # impact_env comes from this checkout, not a wheel
    assert "not from an installed wheel" in capsys.readouterr().err
    video = walk.record_video(tmp_path, steps=12)
    assert video.suffix == ".mp4" and video.read_bytes()[4:8] == b"ftyp"
