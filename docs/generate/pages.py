"""The reference pages' generated parts, kept in the pages themselves so that they read whole in
the repository too: each sits between ``<!-- generated: NAME -->`` and ``<!-- end generated -->``
(or after a bare ``<!-- generated: NAME -->``, the first time), and is made anew from the code.

    python docs/generate/pages.py      # write the pages' generated parts anew (docs/reference/*.md)

The site's build fills them in from the code as it builds (docs/hooks.py); tests/test_docs.py
checks that the copies in the pages are the code's."""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Callable

DOCS = Path(__file__).resolve().parents[1]
BLOCK = re.compile(r"<!-- generated: ([a-z0-9-]+) -->\n(?:.*?<!-- end generated -->)?", re.S)


def generators() -> dict[str, Callable[[], str]]:
    from generate import bridge_reference, cli_reference, config_reference, hdf5_reference

    return {
        "configuration": config_reference.page,
        "cli": cli_reference.page,
        "hdf5": hdf5_reference.page,
        "bridge-api": bridge_reference.page,
    }


def filled(markdown: str, made: dict[str, Callable[[], str]] | None = None) -> str:
    """``markdown`` with each generated part made anew."""
    made = made or generators()

    def block(match: re.Match) -> str:
        name = match.group(1)
        if name not in made:
            raise KeyError(f"no generator for <!-- generated: {name} -->; known: {', '.join(made)}")
        return f"<!-- generated: {name} -->\n{made[name]().rstrip()}\n<!-- end generated -->"

    return BLOCK.sub(block, markdown)


def for_site(markdown: str) -> str:
    """``markdown`` with its generated parts made anew and their markers left out."""
    return re.sub(r"^<!-- (generated: [a-z0-9-]+|end generated) -->\n", "", filled(markdown), flags=re.M)


def pages() -> list[Path]:
    """The pages that hold generated parts."""
    return sorted(p for p in (DOCS / "reference").rglob("*.md") if BLOCK.search(p.read_text(encoding="utf-8")))


def main() -> int:
    made = generators()
    for page in pages():
        text = page.read_text(encoding="utf-8")
        new = filled(text, made)
        if new != text:
            page.write_text(new, encoding="utf-8")
            print(f"wrote {page.relative_to(DOCS.parent)}")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(DOCS))
    sys.exit(main())
