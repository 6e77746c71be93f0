"""mkdocs hooks (mkdocs.yml, ``hooks:``): the reference pages' generated parts, made anew from the code where a
page says ``<!-- generated: NAME -->`` (docs/generate/pages.py), and the repository files that pages link to outside docs/
(the benchmarks' figures), copied into the site."""

from __future__ import annotations

import sys
from pathlib import Path

from mkdocs.plugins import event_priority

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS))

from generate.outside_files import outside_links, pointed_into_site, repository_file  # noqa: E402
from generate.pages import for_site  # noqa: E402


@event_priority(100)  # before mkdocstrings builds its handlers from their config
def on_config(config):
    """The API pages read the package from the checkout, which lays it out as it installs."""
    python = config["plugins"]["mkdocstrings"].config["handlers"].setdefault("python", {})
    python["paths"] = [str(Path(config["docs_dir"]).parent)]
    return config


def on_files(files, config):
    """Every repository file a page links to outside docs/, added to the site under repo/."""
    from mkdocs.structure.files import File

    docs_dir = Path(config["docs_dir"])
    wanted = {
        where
        for page in files.documentation_pages()
        for where in outside_links(docs_dir, page.src_uri, page.content_string).values()
    }
    for where in sorted(wanted):
        files.append(File.generated(config, where, abs_src_path=str(repository_file(docs_dir, where))))
    return files


def on_page_markdown(markdown, page, config, files):
    """The page with its links outside docs/ pointed into the site and its generated parts filled in."""
    links = outside_links(Path(config["docs_dir"]), page.file.src_uri, markdown)
    return for_site(pointed_into_site(markdown, page.file.src_uri, links))
