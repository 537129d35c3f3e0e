"""The documentation: links that lead somewhere, the package's metadata, the example picture."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)\s]+)\)")
#: The project has no public home yet: nothing may point at an invented one.
PLACEHOLDER_HOST = "github.com/tmmaster"


def documents() -> list[Path]:
    """README, CHANGELOG and every page of the documentation site."""
    return [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]


def test_readme_links_point_at_files_of_the_repository() -> None:
    # Relative links: they work in a clone, in the source distribution and on whichever
    # host the repository is published, until the project has a public home.
    links = LINK.findall((ROOT / "README.md").read_text(encoding="utf-8"))
    assert links
    for link in links:
        if link.startswith(("https://", "http://")):
            continue
        path = link.split("#")[0]
        assert (ROOT / path).exists(), f"README.md links to a missing file: {link}"


def test_nothing_points_at_a_placeholder_home() -> None:
    for path in [*documents(), ROOT / "pyproject.toml", ROOT / "mkdocs.yml"]:
        text = path.read_text(encoding="utf-8")
        assert PLACEHOLDER_HOST not in text, f"{path.relative_to(ROOT)} links to {PLACEHOLDER_HOST}"
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "urls" not in project


def test_the_metadata_claims_what_was_checked() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    classifiers = project["classifiers"]
    assert project["requires-python"] == ">=3.11"
    versions = [c.rsplit(" :: ", 1)[1] for c in classifiers if re.search(r":: 3\.\d+$", c)]
    assert versions == ["3.11", "3.12", "3.13"]
    assert [c for c in classifiers if c.startswith("Development Status")] == [
        "Development Status :: 3 - Alpha"
    ]
    assert project["license"] == "MIT"
    assert (ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License")
    assert project["keywords"]


def test_the_example_picture_is_there() -> None:
    image = ROOT / "docs" / "img" / "run.png"
    assert image.read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
