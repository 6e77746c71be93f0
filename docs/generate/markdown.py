"""Small Markdown helpers for the generated pages."""

from __future__ import annotations

from typing import Iterable, Sequence


def cell(text: object) -> str:
    """Text fit for one table cell: one line, pipes escaped."""
    return " ".join(str(text).split()).replace("|", "\\|")


def code(text: object) -> str:
    """Inline code, fenced with enough backticks for the text."""
    text = str(text)
    fence = "``" if "`" in text else "`"
    pad = " " if text.startswith("`") or text.endswith("`") else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def table(headers: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """A Markdown table."""
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(cell(value) for value in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def paragraphs(text: str | None) -> str:
    """A docstring as Markdown: its lines unindented, paragraphs kept."""
    if not text:
        return ""
    lines = text.strip("\n").splitlines()
    indents = [len(line) - len(line.lstrip()) for line in lines[1:] if line.strip()]
    cut = min(indents, default=0)
    body = [lines[0].strip()] + [line[cut:] for line in lines[1:]]
    return "\n".join(body).strip() + "\n"
