# SPDX-License-Identifier: Apache-2.0
"""The documentation site as a reader sees it: built, then rendered in headless Chromium at
1280 px. No page's main column overflows (wide tables and long command lines wrap:
doc/_static/readable.css) and every picture loads.

Chromium and ChromeDriver come from Debian (`apt-get install chromium chromium-driver`); without
them the tests skip with that reason, except where LEADSCREW_REQUIRE_BROWSER is set (.ci/run
installs both and sets it), where a missing browser fails. .ci/run also builds the site first
and hands it over (LEADSCREW_DOC_HTML); without that the tests build it."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"
WIDTH_PX, HEIGHT_PX = 1280, 900
PAGES = ["index.html", "user/listening.html", "user/calibration.html", "user/node.html"]
PAGES += sorted(
    f"user/{p.stem}.html"
    for p in (ROOT / "doc" / "user").glob("*.md")
    if f"user/{p.stem}.html" not in PAGES
)

# What overflows the main column of the loaded page, and which images did not load: one line each.
PROBLEMS_JS = """
const main = document.querySelector('div[role=main]');
if (!main) return ['no main column (div[role=main])'];
const edge = main.getBoundingClientRect().right + 1;
const out = [];
const text = el => (el.textContent || '').trim().replace(/\\s+/g, ' ').slice(0, 50);
if (document.documentElement.scrollWidth > document.documentElement.clientWidth + 1)
  out.push('the page scrolls sideways: ' + document.documentElement.scrollWidth + ' px');
for (const el of main.querySelectorAll('*')) {
  const box = el.getBoundingClientRect();
  if (box.width > 0 && box.right > edge)
    out.push(el.tagName + ' reaches ' + Math.round(box.right) + ' px past the column at '
             + Math.round(edge) + ' px: ' + text(el));
  else if (['PRE', 'TABLE'].includes(el.tagName) || el.classList.contains('wy-table-responsive'))
    if (el.scrollWidth > el.clientWidth + 1)
      out.push(el.tagName + ' scrolls sideways (' + el.scrollWidth + ' > ' + el.clientWidth
               + ' px): ' + text(el));
}
for (const img of document.images)
  if (!(img.complete && img.naturalWidth > 0)) out.push('image did not load: ' + img.src);
return out;
"""


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The doc site built from this checkout, or the one .ci/run built (with -W) before the
    tests and names in LEADSCREW_DOC_HTML: one build per CI run."""
    built = os.environ.get("LEADSCREW_DOC_HTML")
    if built:
        assert (Path(built) / "index.html").is_file(), f"LEADSCREW_DOC_HTML={built}: no site"
        return Path(built)
    out = tmp_path_factory.mktemp("html")
    subprocess.run(
        [sys.executable, "-m", "sphinx", "-q", "-b", "html", str(ROOT / "doc"), str(out)],
        check=True,
        env={**os.environ, "MPLBACKEND": "Agg"},
        timeout=900,
    )
    return out


@pytest.fixture(scope="module")
def browser():
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not shutil.which(p)]
    if missing:
        reason = f"no {', '.join(missing)}: apt-get install chromium chromium-driver"
        if os.environ.get("LEADSCREW_REQUIRE_BROWSER"):
            pytest.fail(reason)
        pytest.skip(reason)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    # Headless, and nothing that reaches out to the network (the machines have none).
    for flag in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--window-size={WIDTH_PX},{HEIGHT_PX}",
    ):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(120)  # a busy CI machine
    yield driver
    driver.quit()


def _open(browser, page: Path) -> None:
    """Load `page` and wait until it is that page, fully loaded, with its main column: on a
    busy machine `get` has been seen to return before the new document was in place."""
    from selenium.webdriver.support.ui import WebDriverWait

    browser.get(page.as_uri())
    WebDriverWait(browser, 120, poll_frequency=0.2).until(
        lambda b: b.execute_script(
            "return document.readyState === 'complete' && location.href === arguments[0]"
            " && document.querySelector('div[role=main]') !== null",
            page.as_uri(),
        )
    )


def _problems(browser, page: Path) -> list[str]:
    _open(browser, page)
    return browser.execute_script(PROBLEMS_JS)


@pytest.mark.parametrize("page", PAGES)
def test_a_page_fits_its_column_at_1280_px_and_its_pictures_load(site, browser, page):
    assert (site / page).is_file(), page
    assert _problems(browser, site / page) == []


def test_the_check_sees_a_wide_table_a_long_line_and_a_missing_picture(site, browser):
    _open(browser, site / "user" / "listening.html")
    browser.execute_script(
        """
        const main = document.querySelector('div[role=main]');
        main.insertAdjacentHTML('beforeend',
          '<pre style="white-space: pre">' + 'x'.repeat(400) + '</pre>'
          + '<table style="width: 3000px"><tr><td>wide</td></tr></table>'
          + '<img src="no_such_picture.png">');
        """
    )
    browser.execute_script("return new Promise(r => setTimeout(r, 500))")  # the image's error
    problems = browser.execute_script(PROBLEMS_JS)
    assert any(p.startswith("PRE scrolls sideways") for p in problems), problems
    assert any(p.startswith("TABLE reaches") for p in problems), problems
    assert any("no_such_picture.png" in p for p in problems), problems
