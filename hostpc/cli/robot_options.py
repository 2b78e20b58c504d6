"""The options that say which robot a command reads its dataset with (``--robot``,
``--base-link``, ``--tip-link``) and how to carry them, with ``--plugin``, into a next
command. Shared by `hostpc fit`, `diagnose` and `predict`, and kept apart from `hostpc
robots` (hostpc.cli.robots, which reads robots and tables) so that their parsers do not
import it (issue 28's quick host: diagnose imports it only with --robot, --prior or --hold)."""

from __future__ import annotations

import argparse


def add_robot_override(parser: argparse.ArgumentParser) -> None:
    """`--robot NAME|FILE.urdf|FILE.json [--base-link L --tip-link L]`: fit a dataset with
    another robot than the one it names (`hostpc fit`, `diagnose`, `predict`)."""
    parser.add_argument("--robot", metavar="NAME|FILE.urdf|FILE.json",
                        help="use this robot instead of the dataset's: a built-in name, a "
                        "URDF file (with --base-link and --tip-link) or a DH/MDH table file "
                        "(docs/robots.md)")
    parser.add_argument("--base-link", help="URDF: the chain's base link")
    parser.add_argument("--tip-link", help="URDF: the chain's tip link (the flange)")


def robot_options(args: argparse.Namespace) -> str:
    """The robot a command read its dataset with (--robot, --base-link, --tip-link), as
    text to append to a next command (" --robot ur10e"; "" when none)."""
    import shlex

    words: list[str] = []
    for option in ("robot", "base_link", "tip_link"):
        value = getattr(args, option, None)
        if value:
            words += [f"--{option.replace('_', '-')}", shlex.quote(str(value))]
    return "".join(f" {w}" for w in words)


def data_options(args: argparse.Namespace) -> str:
    """The options that define how a command read its dataset (--robot, --base-link,
    --tip-link, --plugin), as text to append to a next command (" --robot ur10e"; "" when
    none): a command it suggests reads the same data."""
    import shlex

    plugins = getattr(args, "plugin", None) or []
    return robot_options(args) + "".join(f" --plugin {shlex.quote(str(p))}" for p in plugins)
