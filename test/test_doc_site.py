# SPDX-License-Identifier: Apache-2.0
"""The documentation site (doc/) and the README that points to it.

The README stays short and names the set-up and build commands; every picture a page shows
exists and is small. (The build itself, with warnings as errors and the pages' doctests, runs
in .ci/run; the generated tables are tested in test_settings.py, the architecture tree in
test_layers.py.)"""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "doc"
MAX_README_LINES = 200
MAX_IMAGE_BYTES = 300_000
PAGES = sorted(DOC.glob("**/*.md")) + sorted(DOC.glob("**/*.rst"))
PAGES = [
    p
    for p in PAGES
    if "_build" not in p.parts and "_generated" not in p.parts and "_autosummary" not in p.parts
]


def test_readme_is_short_and_points_to_the_documentation():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= MAX_README_LINES
    for command in (
        "bash scripts/run-demo.sh",
        "bash scripts/run-tests.sh",
        "sphinx-build -W -b html doc doc/_build/html",
    ):
        assert command in readme, command


def test_the_rosdoc2_layout():
    assert (DOC / "conf.py").is_file() and (DOC / "index.rst").is_file()
    for section in ("user", "theory", "reference", "development"):
        assert f"{section}/index" in (DOC / "index.rst").read_text(encoding="utf-8")


def _images(page: Path) -> list[str]:
    text = page.read_text(encoding="utf-8")
    return re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", text) + re.findall(
        r"\.\. (?:figure|image):: (\S+)", text
    )


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(DOC)))
def test_every_picture_of_a_page_exists_and_is_small(page):
    for image in _images(page):
        path = (page.parent / image).resolve()
        assert path.is_file(), f"{page.name}: {image}"
        assert path.stat().st_size <= MAX_IMAGE_BYTES, f"{image}: {path.stat().st_size} bytes"


def test_every_committed_picture_is_shown():
    shown = {(p.parent / i).resolve() for p in PAGES + [ROOT / "README.md"] for i in _images(p)}
    assert set((DOC / "images").glob("*.png")) <= shown
