"""The command-line reference, from the parser the ``noisebo`` command itself uses
(``noisebo.cli.main.build_parser``): every subcommand with its usage and every argument with its
help, default and choices. An argument without help stops the build."""

from __future__ import annotations

import argparse
from pathlib import PurePath

from generate.markdown import code, table

HIDDEN = (argparse._HelpAction, argparse._VersionAction)


class MissingHelp(ValueError):
    """An argument of the command line that says nothing about itself."""


def subcommands(parser: argparse.ArgumentParser) -> tuple[dict[str, argparse.ArgumentParser], dict[str, str]]:
    """The subcommands' parsers and their one-line help, in the order they were added."""
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices), {choice.dest: choice.help or "" for choice in action._choices_actions}


def argument_name(action: argparse.Action) -> str:
    if not action.option_strings:
        return action.metavar or action.dest
    value = action.metavar or action.dest.upper()
    takes = {0: "", "?": f" [{value}]"}.get(action.nargs, f" {value}")
    return ", ".join(action.option_strings) + takes


def default_of(action: argparse.Action) -> str:
    default = action.default
    if action.nargs == 0 or default in (None, argparse.SUPPRESS) or default == []:
        return ""
    return code(str(default) if isinstance(default, PurePath) else default)


def argument_rows(parser: argparse.ArgumentParser, command: str) -> list[tuple]:
    rows = []
    for action in parser._actions:
        if isinstance(action, HIDDEN):
            continue
        if not action.help:
            raise MissingHelp(f"`noisebo {command}`: the argument {argument_name(action)} has no help")
        what = action.help + (f" (one of {', '.join(map(str, action.choices))})" if action.choices else "")
        needed = "required" if action.required else ""
        rows.append((code(argument_name(action)), what, default_of(action), needed))
    return rows


def usage(parser: argparse.ArgumentParser) -> str:
    """The usage line as ``--help`` prints it on a 100-column terminal (the same on every machine)."""
    formatter = argparse.HelpFormatter(parser.prog, width=100)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, prefix="")
    return formatter.format_help().strip()


def command_section(name: str, parser: argparse.ArgumentParser, summary: str) -> str:
    rows = argument_rows(parser, name)
    arguments = table(["argument", "meaning", "default", ""], rows) if rows else "No arguments.\n"
    return f"## `noisebo {name}` {{#{name}}}\n\n{summary[:1].upper() + summary[1:]}.\n\n```text\n{usage(parser)}\n```\n\n{arguments}"


def page() -> str:
    """The generated command-line reference."""
    from noisebo.cli.main import build_parser

    parser = build_parser()
    parsers, helps = subcommands(parser)
    overview = table(
        ["command", "what it does"], [(f"[{code('noisebo ' + name)}](#{name})", helps[name]) for name in parsers]
    )
    head = (
        f"```text\n{usage(parser)}\n```\n\n`noisebo --version` prints the installed version; `noisebo COMMAND --help` "
        f"prints a command's arguments.\n\n{overview}"
    )
    return head + "\n" + "\n".join(command_section(name, p, helps[name]) for name, p in parsers.items())
