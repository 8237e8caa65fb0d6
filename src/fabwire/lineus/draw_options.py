"""Command-line options shared by `fabwire lineus` and the vpype plugin's commands.

Kept apart from `draw_cli`: vpype imports every plugin when it starts, whatever the pipeline, so the plugin's
command definitions must not pull in the drawing machinery (progress bars, pictures, the link) just to declare an
option.
"""

from __future__ import annotations

import click

from fabwire.cli_options import FiniteRange

PEN_Z = click.option("--pen-z", type=FiniteRange(0, 499), default=0.0, show_default=True,
                     help="Pen-down height; about 300 presses less and smears less where the pen lands.")
