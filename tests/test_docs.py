"""The documentation: README links that work on the package index, the example picture."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def test_readme_links_are_absolute_and_point_at_files_that_exist() -> None:
    # PyPI renders README.md without the repository around it: relative links break there.
    urls = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["urls"]
    repo = urls["Homepage"].rstrip("/")
    assert urls["Documentation"].startswith(repo + "/tree/main/")
    links = LINK.findall((ROOT / "README.md").read_text(encoding="utf-8"))
    assert links
    for link in links:
        assert link.startswith(("https://", "http://")), f"relative link in README.md: {link}"
        if link.startswith(repo + "/"):
            where = re.fullmatch(r"(?:tree|blob|raw)/main/([^#]*)(?:#.*)?", link[len(repo) + 1 :])
            assert where, f"README.md link not into the main branch: {link}"
            assert (ROOT / where[1]).exists(), f"README.md links to a missing file: {link}"


def test_the_example_picture_is_there() -> None:
    image = ROOT / "docs" / "img" / "run.png"
    assert image.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
