"""`--drive-option KEY=VALUE` for the commands that open a drive, and the check that it opens."""

from __future__ import annotations

import argparse
from typing import Any

import yaml

from controller.config import MachineConfig
from controller.errors import ConfigError


def add_drive_option_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--drive-option", action="append", default=[], metavar="KEY=VALUE",
                        help="override one of the config's drive.options (repeatable), e.g. "
                             "channel=/dev/ttyACM0")


def parse_drive_options(words: list[str]) -> dict[str, Any]:
    """KEY=VALUE words to a dict; VALUE is read as YAML (1000, 0.002, true, [1, 2], text)."""
    options: dict[str, Any] = {}
    for word in words:
        key, sep, value = word.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--drive-option", word[:40], "expected KEY=VALUE")
        try:
            options[key.strip()] = yaml.safe_load(value) if value else ""
        except yaml.YAMLError:
            options[key.strip()] = value
    return options


def config_with_drive_options(config: MachineConfig, words: list[str]) -> MachineConfig:
    return config.with_drive_options(parse_drive_options(words))


def probe_drive(config: MachineConfig) -> None:
    """Open the configured drive and close it again, enabling nothing: a backend that cannot be
    opened is found before any motion (raises DriveError)."""
    from drivers.registry import make_drive  # late: only the chosen backend's libraries load

    make_drive(config).probe()



