"""What the commands share: how they talk (`Output`: progress bars, ``--quiet``, ``--json``),
the options of more than one command, and the error handling (`run`: one line on stderr and
an exit code).

The exit code is 0 on success, `EXIT_DATA` for bad data (unreadable file, overlapping
input, a failed run), `EXIT_USAGE` for bad usage (unknown option, invalid value),
`EXIT_NOT_CONVERGED` when a jamming run ended without converging (its result is still
written) and `EXIT_INTERRUPTED` when interrupted.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import click

from ..protocols import DISTRIBUTIONS
from ..solvers import backend_names

EXIT_DATA, EXIT_USAGE, EXIT_NOT_CONVERGED = 1, 2, 3
#: Exit code of an interrupted command (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130


class NotConverged(Exception):
    """A jamming run ended without meeting both convergence criteria."""


class Output:
    """How a command talks: progress bars or not, human text or one JSON object."""

    def __init__(self, quiet: bool, as_json: bool) -> None:
        self.quiet = quiet
        self.as_json = as_json

    @property
    def progress(self) -> bool:
        """Whether to show progress bars (on stderr)."""
        return not self.quiet

    def say(self, text: str) -> None:
        """Human text on stdout (nothing with --quiet or --json)."""
        if not self.quiet and not self.as_json:
            click.echo(text)

    def done(self, record: dict, text: str) -> None:
        """The final word: the JSON record with --json, else `text` (kept with --quiet)."""
        if self.as_json:
            click.echo(json.dumps(record, default=_json_default))
        else:
            click.echo(text)


def _json_default(value):
    """JSON for numpy scalars and paths (`json.dumps` ``default``)."""
    if hasattr(value, "item"):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


@contextlib.contextmanager
def stdout_to_stderr() -> Iterator[None]:
    """Send everything written to file descriptor 1 (verbose output of a solver or library)
    to stderr.

    Keeps stdout for the command's own summary, so ``--json`` output stays parseable.
    """
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


@contextlib.contextmanager
def naming(path: Path | None) -> Iterator[None]:
    """Put `path` in front of a ValueError raised inside the block, unless it names it already
    (or `path` is None: no file).

    Errors print one line naming the file at fault: a message from deep in the library
    (an overlapping input found by `jam`, a packing a format cannot hold) does not know
    which file it is about.
    """
    try:
        yield
    except ValueError as error:
        if path is None or str(path) in str(error):
            raise
        raise ValueError(f"{path}: {error}") from error


def output_options(command: Callable) -> Callable:
    """Add ``--quiet`` and ``--json`` to a command (passed on as ``out: Output``)."""

    @functools.wraps(command)
    def wrapper(*args, quiet: bool, as_json: bool, **kwargs):
        out = Output(quiet, as_json)
        with stdout_to_stderr():
            record, text = command(*args, out=out, **kwargs)
        out.done(record, text)
        if record.get("converged") is False:
            raise NotConverged(record.get("status", ""))
        return record

    wrapper = click.option(
        "--json", "as_json", is_flag=True, help="Print a JSON summary on stdout instead of text."
    )(wrapper)
    return click.option("--quiet", "-q", is_flag=True, help="No progress bars.")(wrapper)


def positive(kind: type) -> click.ParamType:
    """A click type for numbers > 0."""
    return click.IntRange(min=1) if kind is int else click.FloatRange(min=0, min_open=True)


def diameter_options(command: Callable) -> Callable:
    """Options --n, --d and the size distribution."""
    options = [
        click.option(
            "--n",
            "n",
            type=click.IntRange(min=2),
            default=256,
            show_default=True,
            help="Number of particles.",
        ),
        click.option(
            "--d", "d", type=click.IntRange(min=2), default=3, show_default=True, help="Dimension."
        ),
        click.option(
            "--distribution",
            type=click.Choice(DISTRIBUTIONS),
            default="monodisperse",
            show_default=True,
            help="Diameter distribution.",
        ),
        click.option(
            "--ratio",
            type=positive(float),
            default=1.4,
            show_default=True,
            help="Bidisperse size ratio (50:50).",
        ),
        click.option(
            "--std",
            type=positive(float),
            default=0.1,
            show_default=True,
            help="Log-normal standard deviation (mean diameter 1).",
        ),
        click.option(
            "--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed."
        ),
    ]
    for option in reversed(options):
        command = option(command)
    return command


def checkpoint_option(command: Callable) -> Callable:
    """Add ``--checkpoint PATH``: save the run's state there, resume from it if it exists."""
    return click.option(
        "--checkpoint",
        type=click.Path(dir_okay=False, path_type=Path),
        help="State file (.npz) saved during the run; an existing one is resumed.",
    )(command)


def final_growth_rate_option(command: Callable) -> Callable:
    """Add ``--final-growth-rate R``: an LS slow end, rate R from the slowdown pressure on."""
    return click.option(
        "--final-growth-rate",
        type=positive(float),
        default=None,
        help="LS slow end: this growth rate once the reduced pressure reaches the slowdown "
        "pressure (1e3 unless set), e.g. 1e-4 with a target pressure of 1e7; the end state is "
        "then a jamming point up to d/p.",
    )(command)


def output_path(option: str = "-o") -> Callable:
    """Add the required output file option `option` (and ``--output``), passed as ``output``."""
    return click.option(
        option,
        "--output",
        "output",
        type=click.Path(dir_okay=False, path_type=Path),
        required=True,
        help="Output file; the extension picks the format.",
    )


def solver_option(command: Callable) -> Callable:
    """Add ``--solver NAME``, one of the registered LP backends."""
    return click.option(
        "--solver",
        type=click.Choice(backend_names()),
        default="highs",
        show_default=True,
        help="LP backend.",
    )(command)


def _one_line(message: str) -> str:
    """`message` on one line, its whitespace runs collapsed to single spaces."""
    return " ".join(str(message).split())


def run(group: click.Group, argv: list[str] | None = None) -> int:
    """Run the command line `group` on `argv` (the process's arguments when None) and return
    the exit code; every error prints one line ``error: <message>`` on stderr.

    Parameters
    ----------
    group : click.Group
        The ``calippso`` command.
    argv : list of str, optional
        The arguments after the program name.

    Returns
    -------
    int
        0 on success (a bare group prints its help), `EXIT_USAGE`, `EXIT_DATA`,
        `EXIT_NOT_CONVERGED` or `EXIT_INTERRUPTED`.
    """
    try:
        value = group.main(args=argv, prog_name="calippso", standalone_mode=False)
        return value if isinstance(value, int) else 0
    except click.exceptions.NoArgsIsHelpError as bare:  # `calippso`, `calippso generate`
        click.echo(bare.ctx.get_help())
        return 0
    except click.UsageError as error:
        click.echo(f"error: {_one_line(error.format_message())}", err=True)
        return EXIT_USAGE
    except click.ClickException as error:
        click.echo(f"error: {_one_line(error.format_message())}", err=True)
        return EXIT_DATA
    except NotConverged as error:
        click.echo(
            f"error: jamming did not converge (result written): {_one_line(error)}", err=True
        )
        return EXIT_NOT_CONVERGED
    except (click.exceptions.Abort, KeyboardInterrupt):
        click.echo("error: interrupted", err=True)
        return 130
    except Exception as error:  # a data error from the library: report it on one line
        name = type(error).__name__
        prefix = "" if isinstance(error, (ValueError, FileNotFoundError)) else f"{name}: "
        click.echo(f"error: {prefix}{_one_line(error)}", err=True)
        return EXIT_DATA
