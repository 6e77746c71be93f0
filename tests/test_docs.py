"""The documentation site builds with `mkdocs build --strict` (no broken link, anchor or page), and
its generated reference pages cannot disagree with the code: the configuration reference names
every field of every config model, and a part of the code with no words stops the build."""

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path
from typing import get_args

import pytest
from pydantic import BaseModel

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def generate():
    """The docs' generators (docs/generate), importable as the mkdocs hook imports them."""
    sys.path.insert(0, str(ROOT / "docs"))
    try:
        import generate

        yield generate
    finally:
        sys.path.remove(str(ROOT / "docs"))


def test_the_site_builds_strictly_outside_the_checkout(tmp_path):
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "--config-file",
            str(ROOT / "mkdocs.yml"),
            "--site-dir",
            str(site),
        ],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert out.returncode == 0, out.stdout + out.stderr
    for page in (
        "reference/configuration",
        "reference/cli",
        "reference/hdf5",
        "reference/bridge-protocol",
        "reference/api/client",
    ):
        html = (site / page / "index.html").read_text()
        assert "generated:" not in html, f"{page}: a marker was left unfilled"
    assert "serve_instrument" in (site / "reference/api/client/index.html").read_text()
    assert (site / "repo/benchmarks/results/forrester_posterior_seed0.png").is_file()


def reachable_models(model: type[BaseModel], seen: dict) -> dict:
    """Every model reachable from ``model`` through its fields, with its field names."""
    if model in seen:
        return seen
    seen[model] = set(model.model_fields)
    for field in model.model_fields.values():
        for sub in models_of(field.annotation):
            reachable_models(sub, seen)
    return seen


def models_of(annotation) -> list[type[BaseModel]]:
    """The models a field's annotation holds (alone, in a union, a tuple or a mapping)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return [annotation]
    return [m for arg in get_args(annotation) for m in models_of(arg)]


def documented_keys(page: str) -> dict[str, set[str]]:
    """{model's qualified name: the last part of every key in its sections' tables}."""
    keys: dict[str, set[str]] = {}
    for section in re.split(r"^### ", page, flags=re.M)[1:]:
        model = re.search(r"^Model: `([\w.]+)`", section, re.M).group(1)
        rows = re.findall(r"^\| `([\w.\[\]]+)` \|", section, re.M)
        keys.setdefault(model, set()).update(row.rsplit(".", 1)[-1] for row in rows)
    return keys


def test_the_configuration_reference_names_every_field_of_every_config_model(generate):
    from generate import config_reference
    from noisebo.config import CampaignConfig

    roots = [CampaignConfig, *(driver.Settings for driver in config_reference.builtin_drivers().values())]
    assert {"forrester", "pfm", "remote"} <= set(config_reference.builtin_drivers())
    models: dict = {}
    for root in roots:
        reachable_models(root, models)
    documented = documented_keys(config_reference.page())
    for model, fields in models.items():
        name = f"{model.__module__}.{model.__qualname__}"
        assert fields <= documented.get(name, set()), f"{name}: {sorted(fields - documented.get(name, set()))}"
    assert len(models) > 20


def test_a_command_line_argument_without_help_stops_the_build(generate):
    from generate import cli_reference

    parser = argparse.ArgumentParser(prog="noisebo run")
    parser.add_argument("--seed", type=int, default=0)
    with pytest.raises(cli_reference.MissingHelp, match="--seed SEED has no help"):
        cli_reference.argument_rows(parser, "run")


def test_a_root_attribute_without_words_stops_the_build(generate):
    from generate import hdf5_reference

    names = [*hdf5_reference.ROOT_ATTRIBUTES, "new_attribute"]
    with pytest.raises(hdf5_reference.Undocumented, match="new_attribute"):
        hdf5_reference.checked(hdf5_reference.ROOT_ATTRIBUTES, names, "root attributes")


def test_the_reference_pages_hold_what_the_code_generates(generate):
    """The pages carry their generated parts, so they read whole in the repository; a copy that
    the code no longer gives fails here (`python docs/generate/pages.py` writes them anew)."""
    from generate import pages

    found = pages.pages()
    assert {p.name for p in found} >= {"cli.md", "configuration.md", "hdf5.md", "bridge-protocol.md"}
    made = pages.generators()
    for page in found:
        text = page.read_text(encoding="utf-8")
        assert "<!-- end generated -->" in text, page
        assert pages.filled(text, made) == text, f"{page} is stale: run python docs/generate/pages.py"
