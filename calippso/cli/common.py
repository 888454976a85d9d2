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
import dataclasses
import functools
import inspect
import json
import os
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..geometry.boundaries import CYLINDER, WALLS, Boundaries
from ..protocols import DISTRIBUTIONS
from ..solvers import backend_names

if TYPE_CHECKING:
    from ..geometry.packing import Packing

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


#: The option of each container kind.
CONTAINER_OPTIONS = {WALLS: "--walls", CYLINDER: "--cylinder"}


@dataclasses.dataclass(frozen=True)
class Container:
    """What ``--walls AXES`` or ``--cylinder AXES`` asked for: a kind and the axes as typed
    (names "x", "y", … or numbers), made into `Boundaries` once the dimension is known."""

    kind: str
    axes: tuple[str, ...]

    @property
    def option(self) -> str:
        """The option as typed, e.g. "--walls x,y"."""
        return f"{CONTAINER_OPTIONS[self.kind]} {','.join(self.axes)}"

    def boundaries(self, d: int) -> Boundaries:
        """The boundaries in dimension `d` (periodic along the other axes).

        Raises
        ------
        click.BadParameter
            An unknown or repeated axis, or a cylinder on other than two axes.
        """
        axes = [int(axis) if axis.isdigit() else axis for axis in self.axes]
        make = Boundaries.walls if self.kind == WALLS else Boundaries.cylinder
        try:
            return make(d, axes)
        except ValueError as error:
            raise click.BadParameter(str(error),
                                     param_hint=f"'{CONTAINER_OPTIONS[self.kind]}'") from None


def _container(kind: str) -> Callable:
    """The click callback of ``--walls``/``--cylinder``: "x,y" to a `Container`."""

    def parse(ctx: click.Context, param: click.Parameter, value: str | None):
        if value is None:
            return None
        axes = tuple(axis.strip().lower() for axis in value.split(",") if axis.strip())
        if not axes:
            raise click.BadParameter("give the axes, e.g. x or x,y", ctx=ctx, param=param)
        return Container(kind, axes)

    return parse


def container_options(command: Callable) -> Callable:
    """Add ``--walls AXES`` and ``--cylinder AXES`` (passed on as ``container``: a
    `Container`, or None for a periodic box)."""

    @functools.wraps(command)
    def wrapper(*args, walls: Container | None, cylinder: Container | None, **kwargs):
        if walls is not None and cylinder is not None:
            raise click.UsageError("--walls and --cylinder exclude each other: give one")
        return command(*args, container=walls or cylinder, **kwargs)

    wrapper = click.option(
        "--cylinder", callback=_container(CYLINDER), metavar="AXES",
        help="A cylinder: the circle inscribed in the box over these two axes (e.g. x,y), "
        "periodic along the others.")(wrapper)
    return click.option(
        "--walls", callback=_container(WALLS), metavar="AXES",
        help="Flat hard walls at 0 and L along these axes (names x, y, z, w or numbers, "
        "comma-separated, e.g. x,y), periodic along the others.")(wrapper)


def with_container(packing: Packing, container: Container | None, source: Path) -> Packing:
    """`packing` with the boundaries `container` asks for.

    Parameters
    ----------
    packing : Packing
        Read from `source`.
    container : Container or None
        ``--walls``/``--cylinder``; None keeps the file's boundaries.
    source : Path
        The file, named in the errors.

    Raises
    ------
    ValueError
        The file's packing has other non-periodic boundaries than the option asks for, or a
        particle lies outside the container asked for.
    """
    if container is None:
        return packing
    wanted = container.boundaries(packing.d)
    if not packing.boundaries.is_periodic and packing.boundaries != wanted:
        raise ValueError(f"{source}: the file's packing has {packing.boundaries.describe()}, "
                         f"{container.option} asks for {wanted.describe()}")
    with naming(source):
        return dataclasses.replace(packing, boundaries=wanted)


def call_with_boundaries(generator: Callable, container: Container | None, d: int, /, *args,
                         **kwargs):
    """`generator(*args, **kwargs)`, with ``boundaries=`` from `container` (in dimension `d`)
    when one is given.

    Raises
    ------
    ValueError
        `container` is given and `generator` takes no ``boundaries`` (it makes periodic
        packings only).
    """
    if container is None:
        return generator(*args, **kwargs)
    if "boundaries" not in inspect.signature(generator).parameters:
        raise ValueError(f"{container.option}: generators.{generator.__name__} makes periodic "
                         "packings only (it takes no boundaries yet)")
    return generator(*args, boundaries=container.boundaries(d), **kwargs)


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
