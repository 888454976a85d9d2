"""``calippso jam``: jam a packing read from a file, write the result.

Its options are the decorators of `jam`; each is passed on to `calippso.jam` in the body.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..routes import ROUTES
from ..settings import (CROSSOVER_MODES, INTERIOR_LP_MIN_COLUMNS, INTERIOR_POINT_SOLVERS,
                        NETWORK_FIRST_MODES, PIVOT_MODES)
from .common import (checkpoint_option, container_options, naming, output_options,
                     output_path, positive, solver_option, with_container)
from .progress import jam_with_progress

if TYPE_CHECKING:
    import numpy as np


def _contacts_of(path: Path) -> np.ndarray:
    """The (M, 2) 'contacts' array of an .npz file (a network hint for `jam`)."""
    import numpy as np

    from ..io.npz import load_arrays

    arrays = load_arrays(path)
    if "contacts" not in arrays:
        raise ValueError("no 'contacts' array in this file (expected a jammed result, or a "
                         "start that carries its contact network)")
    return np.asarray(arrays["contacts"])


def jam_record(result, source, output: Path | None) -> dict:
    """The JSON record of a jamming run: its input, `calippso.analysis.record.run_record`
    (with the box, the jamming category, the pressure and the stress anisotropy), the
    stress tensor (`JammingResult.contact_stress`), the box matrix of a deformable run, the
    boundaries and wall contacts, and the output path."""
    from ..analysis.record import run_record

    return {
        "command": "jam",
        "input": str(source),
        **run_record(result),
        "boundaries": str(result.packing.boundaries),
        "n_wall_contacts": result.n_wall_contacts,
        "route": result.route,
        "displacement_max": result.displacement_max,
        "displacement_median": result.displacement_median,
        "phi_change": result.phi_change,
        "stress": (None if result.contact_stress is None
                   else result.contact_stress.tolist()),
        **({} if result.box_mode == "fixed" and not result.packing.is_sheared else {
            "box_matrix": result.packing.lattice.tolist()}),
        "output": None if output is None else str(output),
    }


@click.command()
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@output_path()
@solver_option
@click.option(
    "--interior-point",
    type=click.Choice(INTERIOR_POINT_SOLVERS),
    default="auto",
    show_default=True,
    help="HiGHS interior point for LPs solved from scratch (auto: HiPO for large LPs when "
    "installed, else IPX; hipo needs calippso[hipo]).",
)
@click.option(
    "--crossover",
    type=click.Choice(CROSSOVER_MODES),
    default="auto",
    show_default=True,
    help="End every LP at a vertex (on), or read each interior solution by complementarity "
    f"and hand its network to Newton (off); auto: off for LPs of {INTERIOR_LP_MIN_COLUMNS:,} "
    "columns (d N + 1) or more.",
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
    "--time-limit",
    type=positive(float),
    default=None,
    help="Stop after the first LP (and its Newton stage) that ends this many seconds into the "
    "loop; the output holds the configuration reached, and with --checkpoint a second call "
    "resumes.",
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
    "--pivots",
    type=click.Choice(PIVOT_MODES),
    default="network_first",
    show_default=True,
    help="Where contact pivots repair an isostatic network whose forces are not all "
    "positive (network_first: in that stage, and in the LP loop with --crossover off; "
    "off: never).",
)
@click.option(
    "--network",
    "network_path",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="An .npz file whose 'contacts' array (M, 2) is tried first as the contact network "
    "(a jammed result, or a start that carries its network).",
)
@click.option(
    "--route",
    type=click.Choice(ROUTES),
    default="lp",
    show_default=True,
    help="lp: the LP loop from the input; relaxed: relax the input as soft spheres first, "
    "then certify its network (a nearby jamming point, fast for inputs compressed at a "
    "constant rate); auto: relaxed where the LP route is predicted slow.",
)
@click.option(
    "--max-displacement",
    type=positive(float),
    default=None,
    help="Refuse a route that moves any particle further than this from the input (mean "
    "diameters); default 0.5 on the relaxed route, no bound on the LP route.",
)
@click.option(
    "--box",
    "box_mode",
    type=click.Choice(["fixed", "deformable"]),
    default="fixed",
    show_default=True,
    help="fixed: the box stays as given; deformable: the box's shape (at a volume that does "
    "not grow) is in every LP too, towards a strictly jammed packing (LP loop alone; "
    "write .npz or .h5 to keep a sheared box).",
)
@click.option(
    "--category",
    "test_category",
    is_flag=True,
    help="Run the jamming-category test (local, collective, strict) on the result and keep "
    "it in OUTPUT, the summary and --json (a deformable run tests its result anyway).",
)
@checkpoint_option
@container_options
@output_options
def jam(input_path, output, solver, interior_point, crossover, tol_gamma, tol_s, max_iters,
        time_limit, precompress_pressure, network_first, pivots, network_path, route,
        max_displacement, box_mode, test_category, checkpoint, container, out):
    """Jam the packing in INPUT with CALiPPSO; write the result to OUTPUT.

    A .npz or .h5 OUTPUT keeps the full result (contacts, forces, rattlers, history).
    --walls/--cylinder set the boundaries of a periodic INPUT (one that has walls already
    must have those).
    """
    import calippso

    from .. import protocols

    network = None
    if network_path is not None:
        with naming(network_path):
            network = _contacts_of(network_path)
    compression = None
    with naming(input_path):
        packing = with_container(calippso.read(input_path), container, input_path)
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
            crossover=crossover,
            tol_gamma=tol_gamma,
            tol_s=tol_s,
            max_iters=max_iters,
            time_limit=time_limit,
            network_first=network_first,
            pivots=pivots,
            network=network,
            checkpoint=checkpoint,
            route=route,
            max_displacement=max_displacement,
            **({"box": box_mode} if box_mode != "fixed" else {}),
        )
        if test_category and result.category is None:
            strongest = "strict" if result.packing.boundaries.periodic.any() else "collective"
            result.category = calippso.jamming_category(result, up_to=strongest).category
    with naming(output):
        written = calippso.write(result, output)
    record = jam_record(result, input_path, written)
    text = f"{result.summary()}\n-> {written}"
    if compression is not None:
        record["precompress"] = {"note": note, "phi": compression.packing.phi,
                                 "reduced_pressure": compression.reduced_pressure,
                                 "steps": compression.steps,
                                 "wall_time": compression.wall_time}
        text = f"{note}\n{text}"
    return record, text
