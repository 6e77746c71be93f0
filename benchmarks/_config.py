"""What every benchmark that runs campaigns shares with the ``noisebo`` command line: its config
loaded and validated the way ``noisebo run`` does before anything runs (``load_config``, then
``instruments.registry.validated`` with the file as the source: the driver checks its settings
and the space must lie inside a simulator's extent), and every input problem reported as one line
``<benchmark>: error: ...`` with exit code 2 and no traceback.

    parser = Parser(description=...)                # argparse, a usage mistake one line, exit 2
    ...
    args = parser.parse_args(argv)
    config, instrument = benchmark_config(parser, args.config, edit=lambda c: c.with_overrides(...))

``edit`` applies the benchmark's own overrides (``--set``, ``--budget``, ``--scan``...) before the
validation, so an override that breaks the config is refused like a bad file. A benchmark scores
against the simulator's truth: an instrument that is not a simulator (remote, manual, a device) is
refused too.
"""

from __future__ import annotations

import argparse
import textwrap
from collections.abc import Callable
from pathlib import Path
from typing import NoReturn

ROOT = Path(__file__).resolve().parents[1]

from noisebo.instruments import build  # noqa: E402
from noisebo.instruments.registry import validated  # noqa: E402
from noisebo.campaign.driver import simulates  # noqa: E402
from noisebo.config import CampaignConfig, ConfigError, load_config, parse_config  # noqa: E402

EXIT_USAGE = 2  # as noisebo/cli/common.py


class _WholeNames(argparse.HelpFormatter):
    """Help wrapped at spaces only: a design's name ("botorch multi-fidelity") stays whole."""

    def _split_lines(self, text: str, width: int) -> list[str]:
        return textwrap.TextWrapper(width, break_on_hyphens=False).wrap(self._whitespace_matcher.sub(" ", text).strip())


class Parser(argparse.ArgumentParser):
    """argparse, but a usage mistake is one line (no usage block), exit 2, as the CLI's; help
    lines break at spaces only."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _WholeNames)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")


def refuse(parser: argparse.ArgumentParser, message) -> NoReturn:
    """One line ``<prog>: error: message`` on stderr, exit 2."""
    parser.exit(EXIT_USAGE, f"{parser.prog}: error: {message}\n")


def validated_config(
    path: str | Path, edit: Callable[[CampaignConfig], CampaignConfig] | None = None
) -> CampaignConfig:
    """The config at ``path`` with ``edit`` applied, validated as ``noisebo run`` validates a file
    (``noisebo/cli/common.py: validated_config``, ``flows/campaign.py: resolve_config``); ``ConfigError`` (its
    message the CLI's, the file named first) otherwise."""
    config = load_config(path)
    if edit is not None:
        config = edit(config)
    return validated(config, str(path))


def benchmark_config(
    parser: argparse.ArgumentParser,
    path: str | Path,
    edit: Callable[[CampaignConfig], CampaignConfig] | None = None,
    simulator: bool = True,
):
    """(config, instrument) for a benchmark: ``validated_config`` and the instrument built from
    it, before anything runs; any problem (a bad file or override, settings the driver refuses, a
    space outside the scan, a scan that cannot be read, no simulator where one is needed) is one
    line and exit 2."""
    try:
        config = validated_config(path, edit)
    except ConfigError as error:
        refuse(parser, error)
    if simulator and config.instrument.kind == "manual":
        refuse(parser, f"{path}: instrument.kind manual: a benchmark needs a simulator (it scores against its truth)")
    try:
        instrument = build(config.instrument)
    except (ConfigError, ValueError, OSError) as error:  # e.g. the driver cannot read its scan
        refuse(parser, f"{path}: {type(error).__name__}: {error}; nothing was measured")
    if simulator and not simulates(instrument):
        refuse(
            parser,
            f"{path}: instrument.kind {config.instrument.kind} is not a simulator: a benchmark needs "
            "one (it scores against its truth)",
        )
    return config, instrument


def same_settings(kept: dict, now: dict) -> bool:
    """Whether the settings a --json was measured with (``kept``) are ``now``: each entry as
    stored, but "config" (a config's JSON dump) as the config it parses to, so a dump written
    before a setting with a default was added still matches a config with that default."""
    if kept.keys() != now.keys():
        return False
    try:
        configs_match = "config" not in now or parse_config(kept["config"]) == parse_config(now["config"])
    except ConfigError:
        return False
    return configs_match and all(kept[k] == now[k] for k in now if k != "config")
