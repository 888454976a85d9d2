"""The ``calippso`` command: generate, jam, report, convert, render, run ensembles, demo.

Thin by design: it parses arguments, calls the library and prints. Progress bars go to
stderr and are silenced by ``--quiet``; ``--json`` prints one JSON object on stdout instead
of the human summary. Errors print one line ``error: <message>`` on stderr; the exit code is
0 on success, 1 for bad data (unreadable file, overlapping input, a failed run), 2 for bad
usage (unknown option, invalid value), 3 when a jamming run ended without converging (its
result is still written).
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import click

from .protocols import DISTRIBUTIONS, PROTOCOLS, make_diameters
from .settings import INTERIOR_POINT_SOLVERS, NETWORK_FIRST_MODES
from .solvers import backend_names

if TYPE_CHECKING:
    import numpy as np

    from .packing import Packing

__all__ = ["main", "cli"]

EXIT_DATA, EXIT_USAGE, EXIT_NOT_CONVERGED = 1, 2, 3


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
    return click.option(
        option,
        "--output",
        "output",
        type=click.Path(dir_okay=False, path_type=Path),
        required=True,
        help="Output file; the extension picks the format.",
    )


def _generation_record(protocol: str, generation, output: Path) -> tuple[dict, str]:
    packing = generation.packing
    record = {
        "command": "generate",
        "protocol": protocol,
        "n": packing.n,
        "d": packing.d,
        "phi": packing.phi,
        "reduced_pressure": generation.reduced_pressure,
        "steps": generation.steps,
        "wall_time": generation.wall_time,
        "status": generation.status,
        "output": str(output),
    }
    text = (
        f"{protocol}: N = {packing.n}, d = {packing.d}, phi = {packing.phi:.6f}, "
        f"p = {generation.reduced_pressure:.3g}, {generation.wall_time:.1f} s "
        f"({generation.status}) -> {output}"
    )
    return record, text


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="calippso")
def cli() -> None:
    """Jam hard-sphere packings exactly with CALiPPSO, and make the packings to jam.

    Exit codes: 0 success, 1 bad data or failed run, 2 bad usage, 3 jamming did not converge.
    """


@cli.group()
def generate() -> None:
    """Make a configuration: ls, fb, mls (closest jamming) or spherocylinders."""


@generate.command("ls")
@diameter_options
@click.option(
    "--pressure",
    type=positive(float),
    default=1e5,
    show_default=True,
    help="Target reduced pressure p = βP/ρ.",
)
@click.option(
    "--growth-rate",
    type=positive(float),
    default=1e-2,
    show_default=True,
    help="Growth rate dσ/dt.",
)
@final_growth_rate_option
@click.option(
    "--slowdown-pressure",
    type=positive(float),
    default=1e3,
    show_default=True,
    help="Reduced pressure at which --final-growth-rate takes over.",
)
@checkpoint_option
@output_path()
@output_options
def generate_ls(
    n, d, distribution, ratio, std, seed, pressure, growth_rate, final_growth_rate,
    slowdown_pressure, checkpoint, output, out
):
    """Lubachevsky–Stillinger compression from random centres to a target pressure."""
    import calippso
    import generators

    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    generation = generators.lubachevsky_stillinger(
        sizes,
        d,
        target_pressure=pressure,
        growth_rate=growth_rate,
        final_growth_rate=final_growth_rate,
        slowdown_pressure=slowdown_pressure,
        seed=seed,
        progress=out.progress,
        checkpoint=checkpoint,
    )
    return _generation_record("ls", generation, calippso.write(generation.packing, output))


@generate.command("quench")
@diameter_options
@click.option(
    "--pressure",
    type=positive(float),
    default=1e-7,
    show_default=True,
    help="Stop once the soft-sphere pressure is at or below this (energy / mean diameter^d).",
)
@checkpoint_option
@output_path()
@output_options
def generate_quench(n, d, distribution, ratio, std, seed, pressure, checkpoint, output, out):
    """Soft-sphere quench to a vanishing pressure, then shrunk to hard contact.

    The start of a large packing: `calippso jam OUTPUT --network OUTPUT` certifies its
    jamming point with no LP. A .npz OUTPUT keeps the overlap network as 'contacts'.
    """
    import calippso
    import generators
    from .atomic import save_npz_atomic

    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    generation = generators.soft_quench(sizes, d, seed=seed, target_pressure=pressure,
                                        progress=out.progress, checkpoint=checkpoint)
    packing = generation.packing
    if output.suffix.lower() == ".npz" and generation.contacts is not None:
        save_npz_atomic(output, {"positions": packing.positions, "diameters": packing.diameters,
                                 "box": packing.box, "contacts": generation.contacts})
        written = output
    else:
        written = calippso.write(packing, output)
    return _generation_record("quench", generation, written)


@generate.command("fb")
@diameter_options
@click.option(
    "--contraction-rate",
    type=positive(float),
    default=1e-3,
    show_default=True,
    help="Force-biased contraction rate τ (slower is denser).",
)
@output_path()
@output_options
def generate_fb(n, d, distribution, ratio, std, seed, contraction_rate, output, out):
    """Force-biased packing from random centres."""
    import calippso
    import generators

    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    generation = generators.force_biased(
        sizes, d, contraction_rate=contraction_rate, seed=seed, progress=out.progress
    )
    return _generation_record("fb", generation, calippso.write(generation.packing, output))


@generate.command("mls")
@diameter_options
@click.option(
    "--input",
    "input_path",
    type=click.Path(path_type=Path),
    help="Start configuration (default: random centres at phi = 0.3).",
)
@click.option(
    "--final-rate", type=positive(float), default=1e-4, show_default=True, help="Final growth rate."
)
@checkpoint_option
@output_path()
@output_options
def generate_mls(
    n, d, distribution, ratio, std, seed, input_path, final_rate, checkpoint, output, out
):
    """Closest jammed configuration (modified LS) of a start configuration."""
    import calippso
    import generators

    if input_path is not None:
        with naming(input_path):
            start = {"start": calippso.read(input_path)}
    else:
        start = {"diameters": make_diameters(n, distribution, ratio=ratio, std=std, seed=seed),
                 "d": d}
    with naming(input_path):
        generation = generators.closest_jamming(
            **start, final_rate=final_rate, seed=seed, progress=out.progress,
            checkpoint=checkpoint
        )
    with naming(output):
        written = calippso.write(generation.packing, output)
    return _generation_record("mls", generation, written)


@generate.command("spherocylinders")
@click.option(
    "--n",
    "n",
    type=click.IntRange(min=2),
    default=500,
    show_default=True,
    help="Number of particles.",
)
@click.option(
    "--aspect-ratio",
    type=click.FloatRange(min=0),
    default=0.4,
    show_default=True,
    help="Cylinder length over diameter γ = l/d.",
)
@click.option(
    "--contraction-rate",
    type=click.FloatRange(0, 1, min_open=True, max_open=True),
    default=1e-4,
    show_default=True,
    help="Contraction rate τ.",
)
@click.option(
    "--initial-density",
    type=click.FloatRange(0, 2, min_open=True, max_open=True),
    default=None,
    help="Nominal density of the start [default: min(1.2, 12/γ), lower if N is too small "
    "for it].",
)
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True)
@checkpoint_option
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Output extended XYZ file (.xyz) with orientations.",
)
@output_options
def generate_spherocylinders(n, aspect_ratio, contraction_rate, initial_density, seed,
                             checkpoint, output, out):
    """Force-biased packing of spherocylinders (d = 3), written as extended XYZ."""
    from generators import spherocylinders

    if output.suffix.lower() != ".xyz":
        raise click.BadParameter(
            "spherocylinders are written as extended XYZ: use a .xyz name", param_hint="'-o'"
        )
    generation = spherocylinders.force_biased(
        n, aspect_ratio, contraction_rate=contraction_rate, initial_density=initial_density,
        seed=seed, progress=out.progress, checkpoint=checkpoint
    )
    spherocylinders.write_xyz(generation.packing, output)
    packing = generation.packing
    record = {
        "command": "generate",
        "protocol": "spherocylinders",
        "n": n,
        "aspect_ratio": aspect_ratio,
        "initial_density": generation.extra["initial_density"],
        "phi": packing.phi,
        "nematic_order": packing.nematic_order(),
        "steps": generation.steps,
        "wall_time": generation.wall_time,
        "status": generation.status,
        "output": str(output),
    }
    text = (
        f"spherocylinders: N = {n}, aspect ratio {aspect_ratio}, phi = {packing.phi:.6f}, "
        f"S = {record['nematic_order']:.3f}, {generation.wall_time:.1f} s -> {output}"
    )
    return record, text


@cli.command()
@click.argument("source", metavar="IN", type=click.Path(exists=True, path_type=Path))
@output_path()
@click.option(
    "--backend",
    type=click.Choice(["auto", "povray", "matplotlib"]),
    default="auto",
    show_default=True,
    help="POV-Ray (ray-traced, d = 3; 'auto' uses it when installed) or matplotlib.",
)
@click.option(
    "--colour-by",
    type=click.Choice(["orientation", "species"]),
    default=None,
    help="Spherocylinders: by axis direction (|u_x|, |u_y|, |u_z| as RGB; the default) or by "
    "aspect ratio. Spheres are coloured by diameter (species), rattlers grey.",
)
@click.option("--size", type=click.IntRange(min=64), default=900, show_default=True,
              help="Width and height in pixels.")
@output_options
def render(source, output, backend, colour_by, size, out):
    """Draw a packing as a PNG with a title, a colour key and the box outline.

    IN is a spherocylinder packing (extended XYZ from `generate spherocylinders`) or a
    packing of spheres (d = 3) or disks (d = 2) in any readable format; a jammed result
    (.npz, .h5, or .xyz written from one) shows its rattlers in grey.
    """
    if output.suffix.lower() != ".png":
        raise click.BadParameter("the picture is a PNG: use a .png name", param_hint="'-o'")
    with naming(source):
        if _holds_spherocylinders(source):
            return _render_spherocylinders(source, output, backend, colour_by or "orientation",
                                           size)
        if colour_by == "orientation":
            raise click.BadParameter("spheres have no orientation: leave it out or use "
                                     "'species'", param_hint="'--colour-by'")
        return _render_spheres(source, output, backend, size)


def _holds_spherocylinders(path: Path) -> bool:
    """Whether `path` is extended XYZ with the axis and length columns of spherocylinders."""
    from .io import SUFFIXES, extxyz

    return (path.is_file() and SUFFIXES.get(path.suffix.lower()) == "extxyz"
            and {"axis", "length"} <= extxyz.column_names(path))


def _render_spherocylinders(source: Path, output: Path, backend: str, colour_by: str,
                            size: int) -> tuple[dict, str]:
    from generators import spherocylinders

    packing = spherocylinders.read_xyz(source)
    written = spherocylinders.render(packing, output, backend=backend, colour_by=colour_by,
                                     size=size)
    record = {"command": "render", "input": str(source), "output": str(written),
              "particles": "spherocylinders", "n": packing.n, "phi": packing.phi,
              "nematic_order": packing.nematic_order()}
    return record, f"{packing.n} spherocylinders, phi = {packing.phi:.6f}: {source} -> {written}"


def _render_spheres(source: Path, output: Path, backend: str, size: int) -> tuple[dict, str]:
    from .reporting.render import render_spheres

    packing, rattlers = _spheres_and_rattlers(source)
    written = render_spheres(packing, output, rattlers=rattlers, backend=backend, size=size)
    kind = "disks" if packing.d == 2 else "spheres"
    record = {"command": "render", "input": str(source), "output": str(written),
              "particles": kind, "n": packing.n, "d": packing.d, "phi": packing.phi,
              "rattlers": None if rattlers is None else int(rattlers.sum())}
    return record, f"{packing.n} {kind}, phi = {packing.phi:.6f}: {source} -> {written}"


def _contacts_of(path: Path) -> np.ndarray:
    """The (M, 2) 'contacts' array of an .npz file (a network hint for `jam`)."""
    import numpy as np

    from .io.npz import load_arrays

    arrays = load_arrays(path)
    if "contacts" not in arrays:
        raise ValueError("no 'contacts' array in this file (expected a jammed result, or a "
                         "start that carries its contact network)")
    return np.asarray(arrays["contacts"])


def _spheres_and_rattlers(source: Path) -> tuple[Packing, np.ndarray | None]:
    """The packing in `source`, and its rattlers where the file holds a jammed result."""
    import calippso
    from .io import SUFFIXES, extxyz, read_result

    kind = SUFFIXES.get(source.suffix.lower())
    if kind in ("npz", "hdf5") and source.is_file():
        with contextlib.suppress(ValueError):  # not a result file: read it as a packing
            result = read_result(source)
            return result.packing, result.rattlers
    packing = calippso.read(source)
    return packing, extxyz.read_rattlers(source) if kind == "extxyz" else None


#: History stages that solve an LP: the ones `JammingResult.iterations` counts (the force
#: clean-up after the loop is one more LP).
LP_STAGES = frozenset({"lp", "cleanup"})
#: How the LP bar names each stage; a stage missing here is shown by its own name.
STAGE_LABELS = {"lp": "LP", "cleanup": "clean-up LP", "newton": "Newton",
                "guess": "network guess"}


class LPProgress:
    """A tqdm bar over LPs showing the stage, √Γ − 1, max |s| and the contact count.

    It is a `jam` callback, called once per history record. Only the records of LP stages
    (`LP_STAGES`) tick the bar, so that its count is the number of LPs the summary reports;
    another stage (the Newton stage, the network guess) shows as the "stage" label beside
    its numbers. The bar appears with the first record, so input rejected before any LP
    prints no bar.
    """

    def __init__(self, enabled: bool, desc: str = "LP") -> None:
        self._enabled = enabled
        self._desc = desc
        self._bar = None
        self.lps = 0

    def __call__(self, record) -> None:
        if not self._enabled:
            return
        stage = str(record["stage"])
        self._show(record)
        if stage in LP_STAGES:
            self._tick(1)
        else:
            self._bar.refresh()

    def catch_up(self, history) -> None:
        """Count the LPs of a finished run that the callback never saw, and show its last record.

        The force clean-up LP runs after the loop, without a callback; the history of a run
        resumed from a checkpoint also holds the LPs solved before it.
        """
        if not self._enabled or not len(history):
            return
        self._show(history[-1])
        self._tick(sum(str(stage) in LP_STAGES for stage in history["stage"]) - self.lps)

    def _show(self, record) -> None:
        """Open the bar if needed and put the record's stage and numbers beside it."""
        if self._bar is None:
            from tqdm.auto import tqdm

            self._bar = tqdm(desc=self._desc, unit=" LP", file=sys.stderr)
        stage = str(record["stage"])
        self._bar.set_postfix(
            {
                "stage": STAGE_LABELS.get(stage, stage),
                "sqrt(G)-1": f"{record['sqrt_gamma_minus_1']:.1e}",
                "max|s|": f"{record['max_displacement']:.1e}",
                "contacts": int(record["n_contacts"]),
            },
            refresh=False,
        )

    def _tick(self, lps: int) -> None:
        self.lps += lps
        self._bar.update(lps)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()


def jam_with_progress(packing, progress: bool, **options):
    """`calippso.jam` with an LP progress bar whose count is the result's number of LPs."""
    import calippso

    bar = LPProgress(progress)
    try:
        result = calippso.jam(packing, callback=bar, **options)
        bar.catch_up(result.history)
        return result
    finally:
        bar.close()


def _jam_record(result, source, output: Path | None) -> dict:
    from .analysis.record import run_record

    return {
        "command": "jam",
        "input": str(source),
        **run_record(result),
        "output": None if output is None else str(output),
    }


@cli.command()
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@output_path()
@click.option(
    "--solver",
    type=click.Choice(backend_names()),
    default="highs",
    show_default=True,
    help="LP backend.",
)
@click.option(
    "--interior-point",
    type=click.Choice(INTERIOR_POINT_SOLVERS),
    default="auto",
    show_default=True,
    help="HiGHS interior point for LPs solved from scratch (auto: HiPO for large LPs when "
    "installed, else IPX; hipo needs calippso[hipo]).",
)
@click.option(
    "--tol-gamma",
    type=positive(float),
    default=1e-12,
    show_default=True,
    help="Converged when √Γ − 1 is below this ...",
)
@click.option(
    "--tol-s",
    type=positive(float),
    default=1e-9,
    show_default=True,
    help="... and max |s| over non-rattlers (mean diameters) is below this.",
)
@click.option(
    "--max-iters",
    type=positive(int),
    default=1000,
    show_default=True,
    help="Largest number of LPs.",
)
@click.option(
    "--precompress",
    "precompress_pressure",
    type=positive(float),
    default=None,
    help="First compress a loose input by Lubachevsky-Stillinger MD to this reduced pressure "
    "(e.g. 1e5), then run the LP loop; with --checkpoint that stage keeps its own state file "
    "(*.precompress.npz).",
)
@click.option(
    "--network-first",
    type=click.Choice(NETWORK_FIRST_MODES),
    default="auto",
    show_default=True,
    help="Before any LP, certify the input's own contact network by Newton (auto: then LPs "
    "if that fails; off: LPs only; require: fail instead of running an LP).",
)
@click.option(
    "--network",
    "network_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="An .npz file whose 'contacts' array (M, 2) is tried first as the contact network "
    "(a jammed result, or a start that carries its network).",
)
@checkpoint_option
@output_options
def jam(input_path, output, solver, interior_point, tol_gamma, tol_s, max_iters,
        precompress_pressure, network_first, network_path, checkpoint, out):
    """Jam the packing in INPUT with CALiPPSO; write the result to OUTPUT.

    A .npz or .h5 OUTPUT keeps the full result (contacts, forces, rattlers, history).
    """
    import calippso

    from . import protocols

    network = None
    if network_path is not None:
        with naming(network_path):
            network = _contacts_of(network_path)
    compression = None
    with naming(input_path):
        packing = calippso.read(input_path)
        if precompress_pressure is not None:
            compression = protocols.precompress(
                packing, precompress_pressure,
                checkpoint=protocols.precompress_checkpoint(checkpoint))
            note = protocols.precompress_note(packing, compression)
            packing = compression.packing
        result = jam_with_progress(
            packing,
            out.progress,
            solver=solver,
            interior_point=interior_point,
            tol_gamma=tol_gamma,
            tol_s=tol_s,
            max_iters=max_iters,
            network_first=network_first,
            network=network,
            checkpoint=checkpoint,
        )
    with naming(output):
        written = calippso.write(result, output)
    record = _jam_record(result, input_path, written)
    text = f"{result.summary()}\n-> {written}"
    if compression is not None:
        record["precompress"] = {"note": note, "phi": compression.packing.phi,
                                 "reduced_pressure": compression.reduced_pressure,
                                 "steps": compression.steps,
                                 "wall_time": compression.wall_time}
        text = f"{note}\n{text}"
    return record, text


@cli.command()
@click.argument(
    "results",
    metavar="RESULT...",
    nargs=-1,
    required=True,
    type=click.Path(path_type=Path),
)
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the report.",
)
@click.option(
    "--model",
    type=click.Choice(["auto", "power_law", "cutoff"]),
    default=None,
    help="Model of every exponent fit: pure power law, power law with exponential cut-off, or "
    "the one a likelihood-ratio test picks (default: power_law for gaps, auto for forces; "
    "docs/analysis.md).",
)
@click.option(
    "--rule",
    type=click.Choice(["bucklers", "weakest", "response"]),
    default="bucklers",
    show_default=True,
    help="Which forces are localised: every force on a buckler, only each buckler's weakest "
    "force, or the contacts whose opening moves one particle (isostatic packings only; "
    "docs/analysis.md).",
)
@output_options
def report(results, output, model, rule, out):
    """Analyse jammed results (.npz/.h5 files, or folders of them such as an ensemble's) and
    write one pooled report to a folder."""
    files, loaded, skipped = read_results(results)
    page = make_report(loaded, output, model=model, rule=rule)
    warnings = json.loads((page.parent / "summary.json").read_text()).get("warnings", [])
    record = {"command": "report", "results": [str(p) for p in files],
              "skipped": [str(p) for p in skipped], "report": str(page), "warnings": warnings}
    lines = [f"report of {len(loaded)} packing(s) -> {page}"]
    if skipped:
        lines.append(f"skipped {len(skipped)} file(s) that hold no result: "
                     + ", ".join(p.name for p in skipped))
    lines += [f"warning: {warning}" for warning in warnings]
    return record, "\n".join(lines)


#: Extensions of the result files `report` looks for in a folder.
RESULT_SUFFIXES = (".npz", ".h5", ".hdf5")


def read_results(paths: tuple[Path, ...]) -> tuple[list[Path], list, list[Path]]:
    """Read the results named by `paths`: the files read, their results, the files skipped.

    A file must be a result file. A folder (such as one made by ``calippso ensemble``) gives
    its `RESULT_SUFFIXES` files, sorted by name; those that hold no result (the state files
    of an unfinished run) are skipped.

    Raises
    ------
    ValueError
        A file that is not a result file, or a folder without one (the message names it).
    """
    from .io import read_result

    files, results, skipped = [], [], []
    for path in paths:
        if not path.is_dir():
            with naming(path):
                results.append(read_result(path))
            files.append(path)
            continue
        before = len(results)
        for candidate in sorted(p for p in path.iterdir()
                                if p.is_file() and p.suffix.lower() in RESULT_SUFFIXES):
            try:
                results.append(read_result(candidate))
            except ValueError:
                skipped.append(candidate)
            else:
                files.append(candidate)
        if len(results) == before:
            raise ValueError(f"{path}: a folder with no result file "
                             f"({', '.join(RESULT_SUFFIXES)}) in it")
    return files, results, skipped


def make_report(results: list, folder: Path, **options) -> Path:
    """`calippso.report`, with a clear error where the reporting package is not installed."""
    import calippso

    try:
        build = calippso.report
    except AttributeError:
        raise click.ClickException("this calippso has no report module (calippso.report)") from None
    return Path(build(results, folder, **options))


@cli.command()
@click.argument("source", metavar="IN", type=click.Path(path_type=Path))
@click.argument("target", metavar="OUT", type=click.Path(path_type=Path))
@output_options
def convert(source, target, out):
    """Convert between file formats (by extension); a full result stays full where OUT can hold it.

    Formats: .npz, .h5/.hdf5 (any d); .xyz/.extxyz, .gsd (d ≤ 3); .dat/.txt (Skoge–Donev,
    any d); .xyzd or a PackingGeneration folder (d = 3).
    """
    import calippso
    from .io import SUFFIXES, read_result

    obj = None
    if SUFFIXES.get(source.suffix.lower()) in ("npz", "hdf5") and source.is_file():
        with contextlib.suppress(ValueError):  # not a result file: read it as a packing
            obj = read_result(source)
    if obj is None:
        with naming(source):
            obj = calippso.read(source)
    with naming(target):
        written = calippso.write(obj, target)
    packing = getattr(obj, "packing", obj)
    kind = "result" if obj is not packing else "packing"
    return (
        {
            "command": "convert",
            "input": str(source),
            "output": str(written),
            "kind": kind,
            "n": packing.n,
            "d": packing.d,
        },
        f"{kind} N = {packing.n}, d = {packing.d}: {source} -> {written}",
    )


@cli.command()
@click.option(
    "--protocol",
    type=click.Choice(PROTOCOLS),
    default="ls",
    show_default=True,
    help="How each start is made (poisson: random, low density).",
)
@diameter_options
@click.option(
    "--pressure",
    type=positive(float),
    default=1e5,
    show_default=True,
    help="LS target reduced pressure.",
)
@final_growth_rate_option
@click.option(
    "--precompress",
    type=positive(float),
    default=None,
    help="Compress every start by Lubachevsky-Stillinger MD to this reduced pressure before "
    "jamming it (for loose fb and poisson starts), e.g. 1e5.",
)
@click.option(
    "--packings",
    type=positive(int),
    default=4,
    show_default=True,
    help="Number of packings (seeds SEED, SEED+1, ...).",
)
@click.option(
    "--solver",
    type=click.Choice(backend_names()),
    default="highs",
    show_default=True,
    help="LP backend.",
)
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Folder for the packings and summary.csv.",
)
@click.option(
    "--workers",
    type=positive(int),
    default=None,
    help="Local worker processes (default: the number of cores).",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    default=None,
    help="Run on a Dask cluster (e.g. tcp://host:8786) instead of local processes; "
    "this process writes the files.",
)
@output_options
def ensemble(
    protocol,
    n,
    d,
    distribution,
    ratio,
    std,
    seed,
    pressure,
    final_growth_rate,
    precompress,
    packings,
    solver,
    output,
    workers,
    scheduler,
    out,
):
    """Many independent generate → jam → analyse runs; resumes a folder made with the same
    parameters (a rerun with other parameters is refused)."""
    from . import ensemble as runs

    spec = runs.EnsembleSpec(
        protocol=protocol,
        n=n,
        d=d,
        distribution=distribution,
        ratio=ratio,
        std=std,
        pressure=pressure,
        final_growth_rate=final_growth_rate,
        precompress=precompress,
        solver=solver,
    )
    seeds = range(seed, seed + packings)
    if scheduler is not None:
        try:
            table = runs.run_on_scheduler(spec, packings, seeds=seeds, out_dir=output,
                                          address=scheduler, progress=out.progress)
        except ImportError:  # dask.distributed missing
            raise click.UsageError(
                "--scheduler needs dask.distributed: pip install 'calippso[ensemble]'"
            ) from None
    else:
        table = runs.run(
            spec, packings, seeds=seeds, out_dir=output, workers=workers, progress=out.progress
        )
    failed = [row for row in table if row["state"] == "failed"]
    record = {
        "command": "ensemble",
        "out_dir": str(output),
        "summary": str(output / runs.SUMMARY),
        "packings": len(table),
        "failed": len(failed),
        "rows": table,
    }
    text = (
        f"{len(table) - len(failed)} of {len(table)} packings done, summary in "
        f"{output / runs.SUMMARY}"
    )
    if failed:
        text += "\n" + "\n".join(f"  seed {row['seed']} failed: {row['error']}" for row in failed)
    return record, text


@cli.command()
@click.option(
    "--n",
    "n",
    type=click.IntRange(min=16),
    default=256,
    show_default=True,
    help="Number of particles (d = 3, monodisperse).",
)
@click.option("--seed", type=click.IntRange(min=0), default=1, show_default=True)
@click.option(
    "-o",
    "--output",
    "output",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("calippso-demo"),
    show_default=True,
    help="Folder for the files.",
)
@output_options
def demo(n, seed, output, out):
    """Generate (LS, p = 1e5), jam and report a small d = 3 packing: about 25 s the first
    time, while Numba compiles the generators, then about 13 s."""
    import calippso
    import generators

    start = time.perf_counter()
    out.say(f"1/3 Lubachevsky-Stillinger compression of N = {n} spheres in d = 3 to p = 1e5")
    generation = generators.lubachevsky_stillinger(
        generators.diameters.monodisperse(n),
        d=3,
        target_pressure=1e5,
        seed=seed,
        progress=out.progress,
    )
    packing_path = calippso.write(generation.packing, output / "start.npz")
    out.say(
        f"    phi = {generation.packing.phi:.6f} in {generation.wall_time:.1f} s -> {packing_path}"
    )
    out.say("2/3 CALiPPSO jamming (one LP per iteration)")
    result = jam_with_progress(generation.packing, out.progress)
    result_path = calippso.write(result, output / "jammed.npz")
    calippso.write(result, output / "jammed.xyz")
    out.say(f"{result.summary()}\n    -> {result_path} (and jammed.xyz for OVITO/ASE)")
    out.say("3/3 report")
    try:
        page = make_report([result], output / "report")
    except ImportError as error:  # matplotlib missing: keep the packing, say why no report
        page, note = None, f"no report ({' '.join(str(error).split())})"
    else:
        note = f"report -> {page}"
    record = {
        "command": "demo",
        **_jam_record(result, packing_path, result_path),
        "report": page,
        "total_wall_time": time.perf_counter() - start,
    }
    return record, f"demo done in {record['total_wall_time']:.0f} s: {note}"


def _one_line(message: str) -> str:
    return " ".join(str(message).split())


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code (errors: one line on stderr)."""
    try:
        value = cli.main(args=argv, prog_name="calippso", standalone_mode=False)
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


if __name__ == "__main__":
    sys.exit(main())
