"""The documentation lives in the repository: every page is reachable from the README, every
link inside it resolves inside the checkout, the settings reference is generated from the
settings themselves, and no file cites a path outside the repository (a clone has only itself)."""

from __future__ import annotations

import importlib.util
import re
import subprocess
from pathlib import Path

import pytest

from appliance.daemon import settings as S

REPO = Path(__file__).resolve().parents[1]
PAGES = [
    "docs/operator-guide.md",
    "docs/settings.md",
    "docs/architecture.md",
    "docs/scan-format.md",
    "docs/method.md",
    "docs/api/README.md",
]
# What a citation of something outside the checkout looks like: the design notes and the
# dissertation's text that the project was started from are not part of a clone.
OUTSIDE = re.compile(
    r"\.\./shared|/work/|shared/docs|shared/seed|seed-brief|toolchain-notes|shared design notes",
    re.IGNORECASE,
)
THIS_FILE = "tests/test_docs.py"  # it has to spell the patterns out
MD_LINK = re.compile(r"\]\(([^)\s]+)\)")


def generator():
    spec = importlib.util.spec_from_file_location(
        "gen_settings_doc", REPO / "scripts" / "gen_settings_doc.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def repo_files() -> list[str]:
    """Tracked files and new ones not ignored: what a commit would carry."""
    out = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard"], cwd=REPO, check=True, capture_output=True, text=True
    ).stdout
    return [name for name in out.splitlines() if (REPO / name).is_file()]


def test_the_settings_reference_is_what_the_generator_writes_from_the_settings():
    committed = (REPO / "docs" / "settings.md").read_text(encoding="utf-8")
    assert committed == generator().render(), "docs/settings.md is out of date: run `make docs`"


def test_every_setting_is_explained_and_listed_with_its_default():
    assert set(S.HELP) == set(S.DEFAULTS), "a setting without its sentence in settings.HELP (or a stale one)"
    page = (REPO / "docs" / "settings.md").read_text(encoding="utf-8")
    for key in S.DEFAULTS:
        assert re.search(rf"^\| `{key}` \|", page, re.M), key


@pytest.mark.parametrize("page", PAGES)
def test_every_page_exists_and_the_readme_links_it(page):
    assert (REPO / page).is_file(), page
    assert f"]({page})" in (REPO / "README.md").read_text(encoding="utf-8"), f"README does not link {page}"


def test_the_readme_links_the_printable_chessboard():
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    for name in ("chessboard.pdf", "chessboard.png"):
        assert f"](appliance/web/static/{name})" in readme
        assert (REPO / "appliance" / "web" / "static" / name).is_file()


@pytest.mark.parametrize("page", ["README.md", *PAGES])
def test_links_in_the_docs_lead_to_files_in_the_checkout(page):
    text = (REPO / page).read_text(encoding="utf-8")
    for target in MD_LINK.findall(text):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue  # a web address or an anchor on the page
        path = ((REPO / page).parent / target.split("#")[0]).resolve()
        assert path.is_relative_to(REPO), f"{page} links outside the repository: {target}"
        assert path.exists(), f"{page} links a missing file: {target}"


def test_no_file_cites_a_path_outside_the_repository():
    found = []
    for name in repo_files():
        if name == THIS_FILE:
            continue
        data = (REPO / name).read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary: images, the PDF
        for n, line in enumerate(data.decode("utf-8", "replace").splitlines(), 1):
            if OUTSIDE.search(line):
                found.append(f"{name}:{n}: {line.strip()[:100]}")
    assert not found, "cites a path outside the repository:\n" + "\n".join(found)


def test_the_outside_pattern_catches_what_it_is_for():
    for citation in (
        "see ../shared/docs/x.md",
        "/work/shared/seed/a.txt",
        "docs/ in the shared design notes",
        "closed forms in seed-brief.md",
    ):
        assert OUTSIDE.search(citation), citation
    for fine in (
        "docs/scan-format.md",
        "shared by the checks",
        "/var/lib/inkslice",
        "the dissertation's samples",
    ):
        assert not OUTSIDE.search(fine), fine
