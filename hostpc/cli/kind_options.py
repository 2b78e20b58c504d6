"""`hostpc calibrate`'s options that belong to a measurement kind's acquisition (the stereo
rig and depth method, the probe's IO, ...).

The kinds declare them (``KindDescriptor.cli_options``, hostpc.dataset.kind_registry); this
module offers them on the command line and turns the given values into the run's
``RunSettings.options`` without knowing any kind. Every registered kind's options are
offered to every method (a method ignores the keys it does not read), except an
``exclusive`` one, which only the kinds declaring it take.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from hostpc.cli.numbers import finite
from hostpc.dataset.kind_registry import kind_descriptors, kind_options
from hostpc.errors import InputError
from hostpc.json_object import JsonObject


def add_kind_options(parser: argparse.ArgumentParser) -> None:
    """Add every registered kind's options (`kind_options`: the default kind's first)."""
    for option in kind_options():
        parser.add_argument(
            option.flag, dest=option.key, metavar=option.metavar, choices=option.choices,
            default=option.default, help=option.help,
            type=finite(least=option.least, most=option.most) if option.number else str)


def kind_option_values(args: argparse.Namespace, method: str,
                       plugins: tuple[str, ...]) -> JsonObject:
    """The run settings' ``options`` block (run.json) from the kinds' options on the command
    line: an option is recorded when given (a file as its absolute path), one with
    ``record_default`` always. InputError for an exclusive option given to another method,
    or an option whose ``needs`` is not met."""
    given = vars(args)
    kinds = kind_descriptors(plugins)
    options: JsonObject = {}
    for option in kind_options():
        value = given[option.key]
        if value is None or value == "" or (value == option.default
                                            and not option.record_default):
            continue
        if option.exclusive:
            takers = [name for name, kind in kinds.items() if option in kind.cli_options]
            if method not in takers:
                raise InputError(f"{option.flag} {value}: only for --method "
                                 f"{', '.join(takers)}")
        if option.needs is not None:
            key, wanted = option.needs
            if given[key] != wanted:
                raise InputError(f"{option.flag} needs --{key.replace('_', '-')} {wanted}")
        options[option.key] = str(Path(value).resolve()) if option.path else value
    return options
