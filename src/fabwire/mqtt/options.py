"""The `--mqtt URL` option's type, shared by `fabwire serve` and `fabwire fleet`."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import click

from fabwire.errors import InputError
from fabwire.mqtt.topics import parse_broker

if TYPE_CHECKING:
    _ParamType = click.ParamType[str]  # generic for type checkers since click 8.2; plain at run time before
else:
    _ParamType = click.ParamType


class BrokerURL(_ParamType):
    """A broker address that `parse_broker` accepts, checked when the command line is read: one that cannot work
    is a usage error (exit 2) before anything starts, its password never shown."""

    name = "URL"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> str:
        try:
            parse_broker(str(value))
        except InputError as exc:
            self.fail(str(exc), param, ctx)
        return str(value)
