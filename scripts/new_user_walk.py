"""The new-user walk: what a new user meets first, run against the installed package from outside the clone.

``make wheel-check`` (``.ci/wheel_check.sh``) runs it after the smoke test, in the fresh venv that has the wheel
and its ``[rl]`` and ``[marl]`` extras, from an empty folder, on copies of the README and the documentation pages:

    python new_user_walk.py README.md docs/*.md

1. Every ``python`` block of those pages runs, as ``tests/docs/test_docs_code.py`` runs it in the suite: a block shown
   on several pages runs once, under the first place it appears; a block marked ``<!-- test: skip, why -->`` on
   the line above its fence is skipped (``slow`` ones run: this is the long check). Each runs in a fresh module
   (``__docs__``, as a reader's script is) and its own empty working folder.
2. A video is recorded with Gymnasium's ``RecordVideo`` (moviepy comes with ``[rl]``), as the Gymnasium docs
   show it, on a registered id.

It refuses to run on a checkout (``impact_env`` must come from ``site-packages``) unless ``--allow-checkout``
(what the suite's own test of this script passes). One line per block; exit 1 listing every failure.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import traceback
import types
from dataclasses import dataclass
from pathlib import Path

FENCE = re.compile(r"^```(\S*)\s*$")
MARK = re.compile(r"^<!-- test: (skip|slow), (\S.*?) -->$")


@dataclass(frozen=True)
class Block:
    where: str  # page:line of the opening fence
    code: str
    mark: tuple[str, str] | None  # ("skip" | "slow", reason)


def python_blocks(pages: list[Path], root: Path) -> list[Block]:
    """The pages' ``python`` blocks in order, each code once (its first place); ``where`` relative to ``root``."""
    seen, out = set(), []
    for page in pages:
        lines = page.read_text(encoding="utf-8").splitlines()
        i = 0
        while i < len(lines):
            opening = FENCE.match(lines[i])
            if not opening:
                i += 1
                continue
            end = next((j for j in range(i + 1, len(lines)) if lines[j].rstrip() == "```"), len(lines))
            code = "\n".join(lines[i + 1:end]) + "\n"
            mark = MARK.match(lines[i - 1].strip()) if i else None
            if opening.group(1) == "python" and code not in seen:
                seen.add(code)
                out.append(Block(f"{page.resolve().relative_to(root.resolve()).as_posix()}:{i + 1}", code,
                                 (mark.group(1), mark.group(2)) if mark else None))
            i = end + 1
    return out


def run_block(block: Block) -> None:
    """Run ``block`` in a fresh module and an empty folder (removed after)."""
    here = os.getcwd()
    module = types.ModuleType("__docs__")
    saved = sys.modules.get("__docs__")
    sys.modules["__docs__"] = module
    with tempfile.TemporaryDirectory(prefix="impact_env_walk_") as folder:
        os.chdir(folder)
        try:
            exec(compile(block.code, block.where, "exec"), module.__dict__)
        finally:
            os.chdir(here)
            if saved is None:
                sys.modules.pop("__docs__", None)
            else:
                sys.modules["__docs__"] = saved


def record_video(folder: Path, env_id: str = "impact_env/Corridor-v0", steps: int = 40) -> Path:
    """One short episode of ``env_id`` recorded by ``gymnasium.wrappers.RecordVideo``; the mp4 it wrote."""
    import gymnasium as gym
    from gymnasium.wrappers import RecordVideo

    import impact_env  # noqa: F401 - registers the ids

    env = RecordVideo(gym.make(env_id, render_mode="rgb_array", max_episode_steps=steps), str(folder),
                      episode_trigger=lambda episode: episode == 0, name_prefix="walk", disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        done = terminated or truncated
    env.close()
    videos = sorted(folder.glob("walk*.mp4"))
    if not videos:
        raise RuntimeError(f"RecordVideo wrote no mp4 in {folder}: {sorted(p.name for p in folder.iterdir())}")
    data = videos[0].read_bytes()
    if len(data) < 1000 or data[4:8] != b"ftyp":
        raise RuntimeError(f"{videos[0]} is not an mp4 ({len(data)} bytes)")
    return videos[0]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("pages", nargs="+", help="the README and the docs pages (copies), Markdown")
    parser.add_argument("--allow-checkout", action="store_true", help="run on a checkout too (the suite's test)")
    args = parser.parse_args(argv)
    import impact_env

    where = Path(impact_env.__file__).resolve()
    if "site-packages" not in where.parts and not args.allow_checkout:
        print(f"impact_env is imported from {where}, not from an installed wheel", file=sys.stderr)
        return 1
    pages = [Path(p) for p in args.pages]
    root = Path(os.path.commonpath([p.resolve().parent for p in pages]))
    blocks = python_blocks(pages, root)
    failed = []
    for block in blocks:
        if block.mark and block.mark[0] == "skip":
            print(f"skipped {block.where}: {block.mark[1]}", flush=True)
            continue
        try:
            run_block(block)
        except BaseException as exc:  # a block's SystemExit or KeyboardInterrupt is a failure of the walk too
            if isinstance(exc, KeyboardInterrupt):
                raise
            failed.append(block.where)
            print(f"FAILED {block.where}:\n{traceback.format_exc()}", flush=True)
        else:
            print(f"ran {block.where}", flush=True)
    with tempfile.TemporaryDirectory(prefix="impact_env_walk_video_") as folder:
        try:
            video = record_video(Path(folder))
        except Exception:
            failed.append("RecordVideo")
            print(f"FAILED RecordVideo:\n{traceback.format_exc()}", flush=True)
        else:
            print(f"RecordVideo wrote {video.name} ({video.stat().st_size:,} bytes)")
    ran = len([b for b in blocks if not (b.mark and b.mark[0] == "skip")])
    if failed:
        print(f"new-user walk: {len(failed)} failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    print(f"new-user walk passed: {ran} code blocks of {len(pages)} pages and a RecordVideo video, with impact_env "
          f"{impact_env.__version__} from {where.parent}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
