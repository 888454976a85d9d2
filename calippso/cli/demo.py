"""``calippso demo``: generate, jam and report a small packing."""

from __future__ import annotations

import time
from pathlib import Path

import click

from .common import output_options
from .jam import jam_record
from .progress import jam_with_progress
from .report import make_report


@click.command()
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
        **jam_record(result, packing_path, result_path),
        "report": page,
        "total_wall_time": time.perf_counter() - start,
    }
    return record, f"demo done in {record['total_wall_time']:.0f} s: {note}"
