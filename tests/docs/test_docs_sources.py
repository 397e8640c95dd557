"""The documentation's sources, checked without building the site (``make docs`` builds it): the generated
environment and command-line pages, the hook's markers (a README section a page would include must exist),
the navigation, and the script that makes the GIFs and figures. The pages' code blocks: test_docs_code.py."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

from tests.paths import ROOT


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


hooks = _load(ROOT / "docs" / "hooks.py", "impact_env_docs_hooks")


@pytest.mark.parametrize("page", hooks.pages(), ids=lambda p: p.slug)
def test_environment_page_is_written_from_the_environment(page):
    from impact_env import envs
    from impact_env.env_docstrings import arguments

    text = hooks.render_page(page)
    assert text.startswith(f"# {page.title}")
    assert f"../img/envs/{page.gif}.gif" in text and (ROOT / "docs" / "img" / "envs" / f"{page.gif}.gif").is_file()
    rows = re.findall(r"<tr><td><code>(\w+)</code>", text)
    assert rows == [a.name for a in arguments(getattr(envs, page.cls))]
    for section in ("## Description", "## Action space", "## Observation space", "## Rewards", "## Arguments",
                    "## Version history"):
        assert section in text, section
    assert "``" not in text and ":class:" not in text
    card = text[text.index('<table class="env-card"><tbody>'):text.index("</tbody></table>")]
    assert "<thead>" not in card and "<th>" not in card  # no empty header row
    assert card.index("env-card") < text.index("env-gif")  # the card before the GIF
    assert card.count("<tr><td>") >= 7 and f'<code class="env-id">{page.env_id}</code>' in card


def test_cli_page_has_every_subcommand():
    text = hooks.cli_help()
    for name in ("scenarios", "generate", "show", "run", "train", "bench", "record", "bc", "dataset", "curves", "plan",
                 "filter"):
        assert f"## {name}\n" in text and f"usage: impact-env {name}" in text
    page = (ROOT / "docs" / "cli.md").read_text()
    assert page.count("<!-- cli-help -->") == 1
    assert "usage: impact-env run" in hooks.on_page_markdown(page, _Page("cli.md"), None, None)


class _Page:
    """What the hook reads of an mkdocs page."""

    def __init__(self, src_path: str) -> None:
        self.file = type("File", (), {"src_path": src_path})()


def test_every_readme_section_the_site_includes_exists():
    for md in (ROOT / "docs").glob("*.md"):
        for heading in re.findall(r"<!-- readme: (.+?) -->", md.read_text()):
            assert hooks.readme_section(heading.strip()), (md.name, heading)


def test_a_missing_readme_section_fails_the_build():
    from mkdocs.exceptions import PluginError

    assert hooks.readme_section("## Install").startswith("With Python")
    with pytest.raises(PluginError, match=r"docs/benchmarks.md: README.md has no heading '## Benchmark'"):
        hooks.on_page_markdown("# B\n\n<!-- readme: ## Benchmark -->\n", _Page("benchmarks.md"), None, None)


def test_every_page_is_in_the_navigation():
    """mkdocs --strict says so too, but only when the site is built; the nav is read here without PyYAML tags."""
    nav = (ROOT / "mkdocs.yml").read_text().split("\nnav:\n", 1)[1]
    listed = set(re.findall(r"([\w/]+\.(?:md|ipynb))", nav))
    pages = {p.relative_to(ROOT / "docs").as_posix() for p in (ROOT / "docs").glob("*.md")} | {"tutorial.ipynb"}
    assert pages <= listed, sorted(pages - listed)
    generated = {f"environments/{p.slug}.md" for p in hooks.pages()} | {"environments/index.md"}
    assert listed - pages == generated, sorted(listed - pages ^ generated)


def test_links_outside_the_docs_become_code():
    text = hooks.repository_links("see [results](results/README.md), [format](scenario_format.md), "
                                  '[web](https://example.org) and <img src="docs/img/corridor.png">')
    assert "`results`" in text and "[format](scenario_format.md)" in text and "(https://example.org)" in text
    assert 'src="img/corridor.png"' in text


def test_media_script_makes_gifs_and_figures(tmp_path):
    import imageio.v3 as iio

    media = _load(ROOT / "scripts" / "make_docs_media.py", "impact_env_docs_media")
    plans = ROOT / "tests" / "data" / "plans" / "bench"  # copies of results/baselines/plans/
    assert media.main(["--only", "throw_and_catch_exp,L", "--max-steps", "12", "--out", str(tmp_path),
                       "--plans", str(plans)]) == 0
    for name in ("throw_and_catch_exp", "L"):
        frames = iio.imread(tmp_path / "envs" / f"{name}.gif", index=None)
        assert frames.shape[0] > 5 and frames.shape[2] == media.GIF_WIDTH_PX
        assert (tmp_path / "scenarios" / f"{name}.png").is_file()
    for kind in ("plan", "execution"):
        assert (tmp_path / "planners" / f"throw_and_catch_exp_{kind}.png").stat().st_size > 10_000


def test_scripted_anchor_rule_delivers_the_cargo_on_every_station():
    import gymnasium as gym

    from impact_env import TETHER_GYM_IDS
    from impact_env.rollout import run_episode

    media = sys.modules.get("impact_env_docs_media") or _load(ROOT / "scripts" / "make_docs_media.py",
                                                              "impact_env_docs_media")
    for env_id in TETHER_GYM_IDS:
        env = gym.make(env_id)
        result = run_episode(env, media.ScriptedAnchors(env.unwrapped.station), seed=0)
        assert result.success, (env_id, result.robustness)


def test_nothing_points_outside_the_repository():
    """Facts the code relies on live in docs/ (background.md): no file names a developers-only document."""
    import subprocess

    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    if not tracked:
        pytest.skip("not a git checkout")
    words = ("paper-" + "scenarios", "shared/" + "reference")
    hits = [f for f in tracked if f.endswith((".py", ".md", ".toml", ".cfg", ".yml", ".sh"))
            and (ROOT / f).is_file() and any(w in (ROOT / f).read_text(errors="ignore") for w in words)]
    assert not hits, hits
