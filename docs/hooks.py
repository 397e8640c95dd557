"""MkDocs hooks of the documentation site: environment pages from the docstrings, the CLI's help, the CHANGELOG.

- ``on_files`` adds one page per environment (``environments/<slug>.md``), written from the environment
  class's docstring (:mod:`impact_env.env_docstrings`) and from the environment itself (spaces, episode length,
  agents), so a page cannot drift from the code: a card (id, make, spaces, episode) with the GIF beside it, the
  docstring's sections and the arguments table (types and defaults from the constructor's signature); and the
  index, a grid of thumbnails (a frame of each GIF) above the table of ids.
- ``on_page_markdown`` replaces ``<!-- cli-help -->`` by every subcommand's ``--help``, ``<!-- changelog -->``
  by the CHANGELOG, and ``<!-- readme: ## Heading -->`` by that section of the README. The pages hold their
  own text (the README says what the package is and links to them), so no page uses the README marker now;
  it stays for a page that wants to quote the README, and a heading the README does not have fails the build.
  Links into the repository outside ``docs/`` become plain code (the site publishes ``docs/`` only).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class EnvPage:
    slug: str
    title: str
    env_id: str
    kind: str  # "gymnasium" or "pettingzoo"
    cls: str  # class name in impact_env.envs
    make: str  # how to construct it
    gif: str  # name of the GIF in img/envs/
    gif_caption: str
    kwargs: tuple[tuple[str, str], ...] = ()  # what the make call passes, for the spaces shown


def pages() -> list[EnvPage]:
    from impact_env import GYM_IDS, TETHER_GYM_IDS

    out = []
    for env_id, name in GYM_IDS.items():
        out.append(EnvPage(name, env_id.split("/")[1], env_id, "gymnasium", "TransportEnv",
                           f'gym.make("{env_id}")', name, f"the expert (MILP plan, replanner, MPC) flying {name}",
                           (("scenario", name),)))
    out.append(EnvPage("transport", "Transport-v0 (any scenario)", "impact_env/Transport-v0", "gymnasium",
                       "TransportEnv", 'gym.make("impact_env/Transport-v0", scenario="my.toml")', "obstacle_avoidance",
                       "the expert on obstacle_avoidance", (("scenario", "obstacle_avoidance"),)))
    out.append(EnvPage("transport_pettingzoo", "transport-v0 (PettingZoo)", "impact_env/transport-v0", "pettingzoo",
                       "TransportParallelEnv", 'transport_v0.parallel_env(scenario="corridor")', "corridor",
                       "the expert on corridor, one agent per robot", (("scenario", "corridor"),)))
    for env_id, name in TETHER_GYM_IDS.items():
        out.append(EnvPage(f"tether_{name}", env_id.split("/")[1], env_id, "gymnasium", "TetherEnv",
                           f'gym.make("{env_id}")', name,
                           f"a scripted anchor sequence on {name} (a hand-written rule, not a planner)",
                           (("station", name),)))
    out.append(EnvPage("tether", "Tether-v1 (any station)", "impact_env/Tether-v1", "gymnasium", "TetherEnv",
                       'gym.make("impact_env/Tether-v1", station="my.toml")', "iss_chain",
                       "a scripted anchor sequence on iss_chain", (("station", "iss_chain"),)))
    out.append(EnvPage("tether_pettingzoo", "tether-v1 (PettingZoo)", "impact_env/tether-v1", "pettingzoo",
                       "TetherParallelEnv", 'tether_v1.parallel_env(station="L")', "L",
                       "a scripted anchor sequence on L", (("station", "L"),)))
    return out


def rst_to_markdown(text: str) -> str:
    """The docstrings' reStructuredText bits as Markdown: ``code``, :class:`~a.b.C`, :mod:`x`."""
    text = re.sub(r":(?:class|func|meth|mod|attr|data|exc):`~?([\w.]+)`",
                  lambda m: f"`{m.group(1).split('.')[-1] if '~' in m.group(0) else m.group(1)}`", text)
    return text.replace("``", "`")


def space_text(space) -> str:
    """A space in one line: Box bounds as scalars when uniform, else the range of its bounds."""
    import numpy as np
    from gymnasium import spaces

    if isinstance(space, spaces.Box):
        low, high = np.asarray(space.low), np.asarray(space.high)
        if np.all(low == low.flat[0]) and np.all(high == high.flat[0]):
            return f"Box({low.flat[0]:g}, {high.flat[0]:g}, {space.shape}, {space.dtype})"
        return (f"Box({space.shape}, {space.dtype}), bounds per entry from {low.min():g} ... {low.max():g} to "
                f"{high.min():g} ... {high.max():g}")
    return repr(space).replace("\n", " ")


def render_page(page: EnvPage) -> str:
    import gymnasium as gym

    import impact_env
    from impact_env import envs
    from impact_env.env_docstrings import arguments, sections

    cls = getattr(envs, page.cls)
    kwargs = dict(page.kwargs)
    if page.kind == "gymnasium":
        env = gym.make(page.env_id, **({} if page.env_id.split("/")[1][:-3] not in ("Transport", "Tether")
                                        else kwargs))
        core = env.unwrapped
        spaces = [("Action space", space_text(env.action_space)),
                  ("Observation space", space_text(env.observation_space))]
        length = (f"{core.horizon_steps} steps of {core.dt_s:g} s ({core.horizon_s:g} s); "
                  f"`max_episode_steps` {env.spec.max_episode_steps}")
        agents = None
    else:
        module = impact_env.transport_v0 if page.cls == "TransportParallelEnv" else impact_env.tether_v1
        core = module.parallel_env(**kwargs)
        agent = core.possible_agents[0]
        spaces = [("Action space (per agent)", space_text(core.action_space(agent))),
                  ("Observation space (per agent)", space_text(core.observation_space(agent))),
                  ("State space", space_text(core.state_space))]
        length = f"{core.horizon_steps} steps of {core.dt_s:g} s ({core.horizon_s:g} s)"
        agents = ", ".join(core.possible_agents)
    shown = ", ".join(f"{k}={v!r}" for k, v in kwargs.items())
    doc = sections(cls)
    card = [("Id", _code(page.env_id, "env-id")), ("Make", _code(page.make))]
    if page.kind == "gymnasium":
        card.append(("Without importing first", _code(f'gym.make("impact_env:{page.env_id}")')))
    card += [(name, _code(rst_to_markdown(value))) for name, value in spaces]
    card.append(("Episode", _html(length.replace("`", "``"))))
    if agents:
        card.append(("Agents", _html(agents)))
    card += [("Class", _code(f"impact_env.envs.{page.cls}")), ("Spaces shown for", _code(shown))]
    # the card first and the GIF beside it, the GIF's height capped: the corridor's (a 4 m x 10 m world, 360 x
    # 900 px) stood above the card and pushed it below the first screen
    lines = [f"# {page.title}", "", '<div class="env-top" markdown>', "",
             '<table class="env-card"><tbody>',
             *(f"<tr><td>{name}</td><td>{value}</td></tr>" for name, value in card),
             "</tbody></table>", "", '<figure class="env-gif" markdown>',
             f'![{page.gif_caption}](../img/envs/{page.gif}.gif){{ width="360" }}',
             f"<figcaption>{page.gif_caption}</figcaption>", "</figure>", "", "</div>", "",
             rst_to_markdown(doc.get("Summary", "")), ""]
    for title in ("Description", "Agents", "Action space", "Observation space", "Rewards", "Starting state",
                  "Episode end", "Info", "Metadata"):
        if doc.get(title):
            lines += [f"## {title}", "", rst_to_markdown(doc[title]), ""]
    lines += ["## Arguments", "", "Keyword arguments of the constructor (and of `gym.make`); the command line's "
              "options carry the same names (`reward_mode` is `--reward-mode`).", "",
              '<table class="arguments"><thead><tr><th>argument</th><th>type</th><th>default</th>'
              "<th>meaning</th></tr></thead><tbody>"]
    for arg in arguments(cls):
        lines.append(f"<tr><td><code>{arg.name}</code></td><td><code>{arg.annotation}</code></td>"
                     f"<td><code>{arg.default}</code></td><td>{_html(arg.description)}</td></tr>")
    lines += ["</tbody></table>", "", "## Version history", "", rst_to_markdown(doc.get("Version history", "")), ""]
    return "\n".join(lines)


def _code(text: str, css: str | None = None) -> str:
    """``text`` as an HTML code element (the card is an HTML table: Markdown's needs a header row)."""
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return f'<code class="{css}">{text}</code>' if css else f"<code>{text}</code>"


def _html(text: str) -> str:
    text = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    text = re.sub(r":(?:class|func|meth|mod|attr|data|exc):`~?([\w.]+)`",
                  lambda m: f"<code>{m.group(1).split('.')[-1]}</code>", text)
    return re.sub(r"``(.+?)``", r"<code>\1</code>", text)


THUMB_PX = 200  # the side of the square box every thumbnail of the environments index fits in


def thumbnail(gif: Path) -> bytes:
    """A PNG of one frame of ``gif`` (two thirds into the episode: bodies in flight), fitted into a
    ``THUMB_PX`` square on white, so every card of the index grid has the same size."""
    import io

    from PIL import Image, ImageOps

    with Image.open(gif) as image:
        image.seek(max(0, int(getattr(image, "n_frames", 1) * 2 / 3) - 1))
        frame = ImageOps.contain(image.convert("RGB"), (THUMB_PX, THUMB_PX))
    square = Image.new("RGB", (THUMB_PX, THUMB_PX), "white")
    square.paste(frame, ((THUMB_PX - frame.width) // 2, (THUMB_PX - frame.height) // 2))
    out = io.BytesIO()
    square.save(out, format="PNG", optimize=True)
    return out.getvalue()


def index_page() -> str:
    rows = "\n".join(f'| [{p.title}]({p.slug}.md) | <code class="env-id">{p.env_id}</code> | {p.kind} | '
                     f"`{p.make}` |" for p in pages())
    cards = "\n".join(f'<a class="env-thumb" href="{p.slug}.html"><img src="thumbs/{p.slug}.png" alt="{p.title}" '
                      f'width="{THUMB_PX}" height="{THUMB_PX}"><span>{p.title}</span></a>' for p in pages())
    return f"""# Environments

Every environment follows Gymnasium's or PettingZoo's API unchanged. Importing `impact_env` registers them;
`gym.make("impact_env:impact_env/Corridor-v0")` imports the package itself. Each page below is written from the
environment's own docstring and constructor, so its arguments table is the code's.

<div class="env-grid">
{cards}
</div>

<div class="env-index" markdown>

| environment | id | API | make |
|---|---|---|---|
{rows}

</div>

## Conventions

- **Keyword names are the CLI's**: `gym.make(..., reward_mode="sparse")` is `impact-env run ... --reward-mode
  sparse`; one name each, no aliases. Any other keyword is an `EnvConfigError` that names the closest
  argument (`reward=` -> "did you mean 'reward_mode'?").
- **Episode length**: the scenario and station ids are registered with `max_episode_steps` equal to the task's
  horizon. The env sets `terminated=True` at the horizon (the task's end; the time left is in the observation,
  so do not bootstrap), and Gymnasium's `TimeLimit` also sets `truncated=True` on that same step: read
  `terminated` first (stable-baselines3 does). A smaller `max_episode_steps` truncates earlier.
- **No silent defaults**: `Transport-v0`, `Tether-v1` and `Tether-v0` need `scenario=` or `station=`, and take
  their `max_episode_steps` from that file. The PettingZoo modules' `parallel_env()`, `env()` and `raw_env()` make
  the corridor and station L when called without one, as `pistonball_v6.env()` does, so PettingZoo's own test
  suite (`api_test`, `parallel_api_test`, `max_cycles_test`) runs on `transport_v0` and `tether_v1` as they are.
- **The episode's clock** is on the env: `env.unwrapped.dt_s`, `horizon_steps`, `horizon_s`.
- **PettingZoo**: versioned modules `impact_env.transport_v0` and `impact_env.tether_v1` with `parallel_env`,
  `env` and `raw_env` (arguments spelled out), `metadata["name"]` per scenario (`transport_corridor_v0`).
  The agents are the scenario's or station's robot names (`R1`, `R2`, ...), so PettingZoo's `api_test` warns
  that it recommends `player_0`-style names; the warning is harmless.
- **Versions**: an id's version is bumped whenever its dynamics, reward or observations change; the
  [changelog](../changelog.md) lists them. The tether ids are at `-v1` (deliver and hold); their `-v0`
  (`impact_env/TetherL-v0` ..., `impact_env/Tether-v0`, `impact_env/tether-v0`) stay registered for one
  release.
"""


def cli_help() -> str:
    """Every subcommand's ``--help``, as the installed ``impact-env`` prints it (COLUMNS fixed for the page): the
    generated part of ``cli.md``."""
    import argparse
    import os

    from impact_env.cli import build_parser

    os.environ["COLUMNS"] = "110"
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    parts = ["### impact-env --help", "", "```text", parser.format_help().rstrip(), "```", ""]
    for name, command in sub.choices.items():
        parts += [f"### {name}", "", "```text", command.format_help().rstrip(), "```", ""]
    return "\n".join(parts)


def on_files(files, config):
    from mkdocs.structure.files import File

    generated: dict[str, str | bytes] = {"environments/index.md": index_page()}
    for page in pages():
        generated[f"environments/{page.slug}.md"] = render_page(page)
        gif = ROOT / "docs" / "img" / "envs" / f"{page.gif}.gif"
        generated[f"environments/thumbs/{page.slug}.png"] = thumbnail(gif)
    for path, content in generated.items():
        files.append(File.generated(config, path, content=content))
    return files


def readme_section(heading: str) -> str:
    """The README's section under ``heading`` (a ``## ...`` or ``### ...`` line), up to the next heading of the
    same or a higher level."""
    text = (ROOT / "README.md").read_text()
    level = len(heading) - len(heading.lstrip("#"))
    lines = text.splitlines()
    try:
        start = lines.index(heading)
    except ValueError:
        raise ValueError(f"README.md has no heading {heading!r}") from None
    out = []
    for line in lines[start + 1:]:
        if line.startswith("#") and len(line) - len(line.lstrip("#")) <= level and line.lstrip("#").startswith(" "):
            break
        out.append(line)
    section = "\n".join(out).strip()
    if not section:
        raise ValueError(f"README.md's section {heading!r} is empty")
    return section


def repository_links(text: str) -> str:
    """Links into the repository outside docs/ become code spans; docs/img paths become relative ones."""
    text = text.replace('src="docs/img/', 'src="img/').replace("](docs/", "](")

    def link(m: re.Match) -> str:
        label, target = m.group(1), m.group(2)
        if re.match(r"https?://|#|mailto:", target) or not re.match(r"[\w./-]+$", target) \
                or (ROOT / "docs" / target.split("#")[0]).exists():
            return m.group(0)
        return label if label.startswith("`") else f"`{label}`"

    return re.sub(r"\[([^\]]+)\]\(([^)\s]+)\)", link, text)


def on_page_markdown(markdown, page, config, files):
    from mkdocs.exceptions import PluginError

    def readme(m: re.Match) -> str:
        try:
            return repository_links(readme_section(m.group(1).strip()))
        except ValueError as error:  # a page must not silently lose the section it includes
            raise PluginError(f"docs/{page.file.src_path}: {error}") from None

    markdown = re.sub(r"<!-- readme: (.+?) -->", readme, markdown)
    if "<!-- cli-help -->" in markdown:
        markdown = markdown.replace("<!-- cli-help -->", cli_help())
    if "<!-- changelog -->" in markdown:
        changelog = (ROOT / "CHANGELOG.md").read_text().split("\n", 1)[1]
        markdown = markdown.replace("<!-- changelog -->", repository_links(changelog))
    return markdown
