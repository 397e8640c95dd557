"""Checks of the built documentation site (``make docs-check``, after ``make docs``; not part of ``make test``).

- Every link and image of every page resolves: relative targets to files of the site, ``#anchors`` to ids of the
  target page. External links are only checked for their form (this project's machines have no open network).
- In headless Chromium (Debian's chromium and chromedriver, driven by selenium), an environment page shows its
  GIF (loaded, animated, drawn on screen: the screenshot is not blank where the GIF is) and its arguments table.
  The screenshots are saved in ``site/_checks/``. Without a browser the check is skipped, unless
  ``IMPACT_ENV_REQUIRE_BROWSER=1`` (as CI sets it), which makes a missing browser a failure.
"""

from __future__ import annotations

import functools
import http.server
import os
import re
import shutil
import threading
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import numpy as np
import pytest

from tests.paths import ROOT

SITE = ROOT / "site"
pytestmark = pytest.mark.skipif(not (SITE / "index.html").is_file(), reason="build the site first: make docs")


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.targets: list[str] = []
        self.ids: set[str] = set()

    def handle_starttag(self, tag, attrs):
        for key, value in attrs:
            if key == "id" and value:
                self.ids.add(value)
            if value and ((key == "href" and tag in ("a", "link")) or (key == "src" and tag in ("img", "script"))):
                self.targets.append(value)


@functools.cache
def _parse(page: Path) -> _Links:
    parser = _Links()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser


def _pages() -> list[Path]:
    return sorted(p for p in SITE.rglob("*.html") if "_checks" not in p.parts)


def test_every_link_and_image_resolves():
    problems, external = [], set()
    for page in _pages():
        for target in _parse(page).targets:
            parts = urlsplit(target)
            if parts.scheme in ("http", "https", "mailto"):
                assert parts.scheme == "mailto" or parts.netloc, f"{page}: malformed link {target!r}"
                external.add(target)
                continue
            if parts.scheme or target.startswith("//"):
                problems.append(f"{page.relative_to(SITE)}: unexpected link {target!r}")
                continue
            if not parts.path:
                path = page
            elif parts.path.startswith("/"):  # site-root links (the 404 page's)
                path = SITE / unquote(parts.path).lstrip("/")
            else:
                path = (page.parent / unquote(parts.path)).resolve()
            if path.is_dir():
                path = path / "index.html"
            if not path.is_file():
                problems.append(f"{page.relative_to(SITE)}: {target!r} does not exist")
            elif parts.fragment and path.suffix == ".html" and unquote(parts.fragment) not in _parse(path).ids:
                problems.append(f"{page.relative_to(SITE)}: {target!r} has no anchor #{parts.fragment}")
    assert not problems, "\n".join(problems)
    assert len(_pages()) >= 20


def test_environment_pages_have_gif_and_arguments_table():
    from impact_env import GYM_IDS, TETHER_GYM_IDS

    for slug in [*GYM_IDS.values(), *(f"tether_{s}" for s in TETHER_GYM_IDS.values())]:
        html = (SITE / "environments" / f"{slug}.html").read_text()
        assert re.search(r'<img[^>]+src="\.\./img/envs/[\w]+\.gif"', html), slug
        assert '<table class="arguments">' in html and "<th>default</th>" in html, slug
        assert "Version history" in html and "max_episode_steps" in html, slug
        assert "<td>Observation space</td>" in html and "<td>Episode</td>" in html, slug  # the summary table


# ------------------------------------------------------------------------------------------------- browser


def _browser_paths() -> tuple[str, str] | None:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (chromium, driver) if chromium and driver else None


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    paths = _browser_paths()
    if paths is None:
        if os.environ.get("IMPACT_ENV_REQUIRE_BROWSER") == "1":
            pytest.fail("headless Chromium is required (apt-get install chromium chromium-driver)")
        pytest.skip("no chromium/chromedriver on this machine")
    selenium = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = selenium.ChromeOptions()
    options.binary_location = paths[0]
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1280,2400", "--force-device-scale-factor=1",
                 f"--user-data-dir={tmp_path_factory.mktemp('chromium')}"):
        options.add_argument(flag)
    driver = selenium.Chrome(options=options, service=Service(executable_path=paths[1]))
    driver.set_page_load_timeout(60)
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(SITE))
    handler.log_message = lambda *args: None
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield driver, f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        driver.quit()
        server.shutdown()
        server.server_close()


@pytest.mark.parametrize("slug, env_class", [("corridor", "TransportEnv"), ("tether_L", "TetherEnv")])
def test_an_environment_page_shows_its_gif_and_arguments_table_in_chromium(browser, slug, env_class):
    import impact_env.envs as envs
    from impact_env.env_docstrings import arguments as constructor_arguments

    arguments = len(constructor_arguments(getattr(envs, env_class)))  # the rows the page was generated from
    from matplotlib.image import imread
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import WebDriverWait

    driver, base = browser
    driver.get(f"{base}/environments/{slug}.html")
    gif = driver.find_element(By.CSS_SELECTOR, "img[src$='.gif']")
    WebDriverWait(driver, 30).until(lambda d: d.execute_script(
        "return arguments[0].complete && arguments[0].naturalWidth > 0", gif))
    driver.execute_script("arguments[0].scrollIntoView({block: 'start'})", gif)
    rect = driver.execute_script("const r = arguments[0].getBoundingClientRect();"
                                 "return [r.left, r.top, r.width, r.height, arguments[0].naturalWidth];", gif)
    left, top, width, height, natural = rect
    assert natural == 360 and width >= 200 and height >= 200, rect
    table = driver.find_element(By.CSS_SELECTOR, "table.arguments")
    headers = [th.text.strip() for th in table.find_elements(By.CSS_SELECTOR, "thead th")]
    assert headers == ["argument", "type", "default", "meaning"]
    rows = table.find_elements(By.CSS_SELECTOR, "tbody tr")
    assert len(rows) == arguments and table.is_displayed()
    assert rows[0].find_elements(By.TAG_NAME, "td")[0].text in ("scenario", "station")

    out = SITE / "_checks"
    out.mkdir(exist_ok=True)
    shot = out / f"{slug}.png"
    driver.save_screenshot(str(shot))
    pixels = imread(shot)[..., :3]
    region = pixels[int(top) + 5:int(top + height) - 5, int(left) + 5:int(left + width) - 5]
    assert region.size, rect
    # the GIF is drawn: many distinct colours where it sits, not the page's blank background
    assert region.std() > 0.05 and len(np.unique(region.reshape(-1, 3), axis=0)) > 20
    driver.execute_script("arguments[0].scrollIntoView({block: 'start'})", table)
    driver.save_screenshot(str(out / f"{slug}_arguments.png"))
