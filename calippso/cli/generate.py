"""``calippso generate``: make a configuration (ls, quench, fb, mls, random,
spherocylinders).

``--walls``/``--cylinder`` pass ``boundaries=`` to a generator that takes it, and are refused
in one line by one that does not (`common.call_with_boundaries`)."""

from __future__ import annotations

from pathlib import Path

import click

from ..protocols import make_diameters
from .common import (call_with_boundaries, checkpoint_option, container_options,
                     diameter_options, final_growth_rate_option, naming, output_options,
                     output_path, positive, with_container)

#: Packing fraction of the Poisson centres of ``generate random``, before the shrink.
RANDOM_START_PHI = 0.3
#: Values of ``generate quench --minimiser`` (those of `generators.soft_quench`, which the
#: command does not import before it runs).
QUENCH_MINIMISERS = ("auto", "fire", "lbfgs", "newton")


def _generation_record(protocol: str, generation, output: Path) -> tuple[dict, str]:
    """The JSON record and the text summary of a generation written to `output`."""
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
        "boundaries": str(packing.boundaries),
        "output": str(output),
    }
    container = "" if packing.boundaries.is_periodic else f", {packing.boundaries.describe()}"
    text = (
        f"{protocol}: N = {packing.n}, d = {packing.d}{container}, phi = {packing.phi:.6f}, "
        f"p = {generation.reduced_pressure:.3g}, {generation.wall_time:.1f} s "
        f"({generation.status}) -> {output}"
    )
    return record, text


@click.group()
def generate() -> None:
    """Make a configuration: ls, quench (soft spheres), fb, mls (closest jamming), random
    (Poisson centres shrunk to no overlap) or spherocylinders."""


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
@container_options
@output_path()
@output_options
def generate_ls(
    n, d, distribution, ratio, std, seed, pressure, growth_rate, final_growth_rate,
    slowdown_pressure, checkpoint, container, output, out
):
    """Lubachevsky–Stillinger compression from random centres to a target pressure."""
    import calippso
    import generators

    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    generation = call_with_boundaries(
        generators.lubachevsky_stillinger,
        container,
        d,
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
    default=None,
    help="Stop once the soft-sphere pressure is at or below this (energy / mean diameter^d). "
    "Default: 1e-6 in a periodic box with N <= 4096 in d = 3, 4; else 1e-7.",
)
@click.option(
    "--minimiser",
    type=click.Choice(QUENCH_MINIMISERS),
    default="auto",
    show_default=True,
    help="Minimiser of the enthalpy: FIRE, L-BFGS, auto (chosen by the dimension), or newton "
    "(auto's, then a damped Newton in turn; docs/generators.md).",
)
@checkpoint_option
@container_options
@output_path()
@output_options
def generate_quench(n, d, distribution, ratio, std, seed, pressure, minimiser, checkpoint,
                    container, output, out):
    """Soft-sphere quench to a vanishing pressure, then shrunk to hard contact.

    The start of a large packing: `calippso jam OUTPUT --network OUTPUT` certifies its
    jamming point with no LP. A .npz OUTPUT keeps the overlap network as 'contacts'.
    """
    import calippso
    import generators
    from ..atomic import save_npz_atomic
    from ..geometry.packing import packing_arrays

    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    generation = call_with_boundaries(generators.soft_quench, container, d, sizes, d, seed=seed,
                                      target_pressure=pressure, progress=out.progress,
                                      checkpoint=checkpoint, minimiser=minimiser)
    packing = generation.packing
    if output.suffix.lower() == ".npz" and generation.contacts is not None:
        save_npz_atomic(output, {**packing_arrays(packing), "contacts": generation.contacts})
        written = output
    else:
        written = calippso.write(packing, output)
    record, text = _generation_record("quench", generation, written)
    record["minimiser"] = generation.extra["minimiser"]
    return record, f"{text} [{record['minimiser']}]"


@generate.command("fb")
@diameter_options
@click.option(
    "--contraction-rate",
    type=positive(float),
    default=1e-3,
    show_default=True,
    help="Force-biased contraction rate τ (slower is denser).",
)
@container_options
@output_path()
@output_options
def generate_fb(n, d, distribution, ratio, std, seed, contraction_rate, container, output, out):
    """Force-biased packing from random centres."""
    import calippso
    import generators

    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    generation = call_with_boundaries(
        generators.force_biased, container, d, sizes, d, contraction_rate=contraction_rate,
        seed=seed, progress=out.progress
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
@container_options
@output_path()
@output_options
def generate_mls(
    n, d, distribution, ratio, std, seed, input_path, final_rate, checkpoint, container, output,
    out
):
    """Closest jammed configuration (modified LS) of a start configuration."""
    import calippso
    import generators

    if input_path is not None:
        with naming(input_path):
            start = {"start": with_container(calippso.read(input_path), container, input_path)}
        container = None                      # the start carries the boundaries
    else:
        start = {"diameters": make_diameters(n, distribution, ratio=ratio, std=std, seed=seed),
                 "d": d}
    with naming(input_path):
        generation = call_with_boundaries(
            generators.closest_jamming, container, d, **start, final_rate=final_rate,
            seed=seed, progress=out.progress, checkpoint=checkpoint
        )
    with naming(output):
        written = calippso.write(generation.packing, output)
    return _generation_record("mls", generation, written)


@generate.command("random")
@diameter_options
@click.option(
    "--phi",
    type=click.FloatRange(0, 1, min_open=True, max_open=True),
    default=RANDOM_START_PHI,
    show_default=True,
    help="Packing fraction of the random centres, before the shrink.",
)
@container_options
@output_path()
@output_options
def generate_random(n, d, distribution, ratio, std, seed, phi, container, output, out):
    """Random start: Poisson centres inside the container, every diameter then shrunk by one
    factor until nothing overlaps (a tiny packing fraction; jam it as it is)."""
    import time

    import calippso
    import generators
    from ..geometry.neighbors import contact_shrink

    began = time.perf_counter()
    sizes = make_diameters(n, distribution, ratio=ratio, std=std, seed=seed)
    points = call_with_boundaries(generators.poisson, container, d, sizes, d, phi=phi,
                                  seed=seed)
    shrink = contact_shrink(points.positions, points.diameters, points.box)
    packing = points.scaled_to_phi(points.phi * shrink ** d)
    written = calippso.write(packing, output)
    seconds = time.perf_counter() - began
    container_text = ("" if packing.boundaries.is_periodic
                      else f", {packing.boundaries.describe()}")
    record = {"command": "generate", "protocol": "random", "n": packing.n, "d": packing.d,
              "phi": packing.phi, "phi_before_shrink": phi, "wall_time": seconds,
              "boundaries": str(packing.boundaries), "output": str(written)}
    text = (f"random: N = {packing.n}, d = {packing.d}{container_text}, phi = {packing.phi:.3g} "
            f"(Poisson centres at phi = {phi:g}, shrunk to no overlap), {seconds:.1f} s "
            f"-> {written}")
    return record, text


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
