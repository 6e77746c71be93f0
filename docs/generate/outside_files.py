"""Files of the repository outside docs/ that a page links to (the benchmarks' figures under
benchmarks/results/): copied into the site under repo/ and the links pointed there, so that a
page's relative links work both on GitHub and in the built site."""

from __future__ import annotations

import posixpath
import re
from pathlib import Path

LINK = re.compile(r"(\]\()((?:\.\./)+[^)\s#]+)(\))")
SITE_FOLDER = "repo"


def site_path(docs_dir: Path, page_uri: str, target: str) -> str | None:
    """Where the file a page links to lands in the site, or None when the link stays in docs/ or
    names no file."""
    repo = docs_dir.parent.resolve()
    path = (docs_dir / posixpath.dirname(page_uri) / target).resolve()
    if path.is_relative_to(docs_dir.resolve()) or not path.is_relative_to(repo) or not path.is_file():
        return None
    return f"{SITE_FOLDER}/{path.relative_to(repo).as_posix()}"


def repository_file(docs_dir: Path, where: str) -> Path:
    """The repository file whose copy lands at ``where`` in the site."""
    return docs_dir.parent.resolve() / where.removeprefix(f"{SITE_FOLDER}/")


def outside_links(docs_dir: Path, page_uri: str, markdown: str) -> dict[str, str]:
    """{link as written: its site path} for every link of the page to a file outside docs/."""
    found = {}
    for _, target, _ in LINK.findall(markdown):
        where = site_path(docs_dir, page_uri, target)
        if where is not None:
            found[target] = where
    return found


def pointed_into_site(markdown: str, page_uri: str, links: dict[str, str]) -> str:
    """The page with each outside link pointed at the file's copy in the site."""
    here = posixpath.dirname(page_uri) or "."

    def replaced(match: re.Match) -> str:
        target = match.group(2)
        if target not in links:
            return match.group(0)
        return f"{match.group(1)}{posixpath.relpath(links[target], here)}{match.group(3)}"

    return LINK.sub(replaced, markdown)
