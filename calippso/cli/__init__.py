"""The ``calippso`` command: generate, jam, report, convert, render, run ensembles, demo.

One module per command group (`generate`, `jam`, `report`, `convert`, `render`,
`ensemble`, `demo`) holds its options, as the decorators of its command, and its body; the
options and output of several commands, and the error handling, are in `common`; the LP
progress bar in `progress`. This module assembles the group (`cli`) and runs it (`main`).

Thin by design: it parses arguments, calls the library and prints. Progress bars go to
stderr and are silenced by ``--quiet``; ``--json`` prints one JSON object on stdout instead
of the human summary. Errors print one line ``error: <message>`` on stderr; the exit code is
0 on success, 1 for bad data (unreadable file, overlapping input, a failed run), 2 for bad
usage (unknown option, invalid value), 3 when a jamming run ended without converging (its
result is still written).
"""

from __future__ import annotations

import click

from . import convert, demo, ensemble, generate, jam, render, report
from .common import run

__all__ = ["main", "cli"]


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="calippso")
def cli() -> None:
    """Jam hard-sphere packings exactly with CALiPPSO, and make the packings to jam.

    Exit codes: 0 success, 1 bad data or failed run, 2 bad usage, 3 jamming did not converge.
    """


for _command in (generate.generate, jam.jam, report.report, convert.convert, render.render,
                 ensemble.ensemble, demo.demo):
    cli.add_command(_command)


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (errors: one line on stderr)."""
    return run(cli, argv)
