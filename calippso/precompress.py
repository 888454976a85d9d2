"""Optional first stage of `jam`: compress a loose input by Lubachevsky–Stillinger (LS) MD.

From a loose start (a force-biased packing at φ ≈ 0.60, a random one at φ ≈ 0.2) the LP
loop crawls: every LP ends at a configuration that is jammed to first order, and the next
one gains only what the neglected |s|² term opened, ~1e-5 in √Γ per LP, so hundreds of LPs
are needed. Event-driven LS compression (`generators.lubachevsky_stillinger`) takes such a
start to a reduced pressure of 1e5 in seconds, keeping the particles, their order, the box
and the diameter ratios; the LP loop then starts close to jamming. The jammed packing is the
CALiPPSO fixed point reached from the compressed state, not from the input itself.

`generators` (and with it numba) is imported only when this stage runs.
"""

from __future__ import annotations

import os
from pathlib import Path

from .packing import Packing

__all__ = ["precompress", "precompress_checkpoint"]

#: Seed of the LS velocities: the stage is deterministic, so a resumed run repeats it exactly.
LS_SEED = 0


def precompress_checkpoint(checkpoint: str | os.PathLike | None) -> Path | None:
    """The LS stage's own checkpoint file beside the loop's: ``run.npz`` → ``run.precompress.npz``."""
    if checkpoint is None:
        return None
    path = Path(checkpoint)
    return path.with_name(f"{path.stem}.precompress.npz")


def precompress(packing: Packing, pressure: float,
                checkpoint: str | os.PathLike | None = None) -> tuple[Packing, str]:
    """Compress `packing` by LS event-driven MD until the reduced pressure exceeds `pressure`.

    Parameters
    ----------
    packing : Packing
        Overlap-free start (round-off overlaps of a few ulps are removed by a uniform shrink).
    pressure : float
        Target reduced pressure βP/ρ; 1e5 leaves gaps ~1e-5 of a diameter.
    checkpoint : str or PathLike, optional
        The LS run's checkpoint file (resumed if it exists, see `generators.checkpoint`).

    Returns
    -------
    Packing
        The compressed packing: same particles in the same order, same box, diameters grown by
        one common factor.
    str
        A note for the jamming status: φ before and after, pressure, collisions, wall time.
    """
    try:
        import generators
    except ImportError as error:  # pragma: no cover - generators ships with calippso
        raise ImportError("precompress_pressure needs the `generators` package (numba)") from error
    run = generators.lubachevsky_stillinger(packing, target_pressure=pressure, seed=LS_SEED,
                                            checkpoint=checkpoint)
    compressed = run.packing
    note = (f"input compressed by Lubachevsky-Stillinger MD before the LP loop: phi "
            f"{packing.phi:.6f} -> {compressed.phi:.6f}, reduced pressure "
            f"{run.reduced_pressure:.2e}, {run.collisions / packing.n:.0f} collisions per "
            f"particle, {run.wall_time:.1f} s")
    return compressed, note
