"""`JammingResult`: what `calippso.jam` returns, and its `.npz` storage.

Keys of the `.npz` file written by `JammingResult.save` (all arrays; scalars are 0-d arrays):

==========================  ===============  ===============================================
key                         shape / dtype    meaning
==========================  ===============  ===============================================
positions                   (N, d) float64   jammed centres, wrapped into [0, L)
diameters                   (N,) float64     jammed diameters
box                         (d,) float64     box side lengths
contacts                    (M, 2) int64     contact pairs (i < j) among stable particles
forces                      (M,) float64     contact force magnitudes, mean 1
rattlers                    (N,) bool        True for rattlers
converged                   () bool          the run ended at a jamming point (`stop_reason`)
iterations                  () int64         number of LPs solved
status                      () str           one sentence on how the run ended
stop_reason                 () str           `calippso.history.StopReason` value
notes                       () str           the notes of the run, one per line
wall_time                   () float64       seconds from the call to the verified result
force_balance               () float64       max_i |Σ_j f_ij n_ij| / mean force (stable i)
dual_normalization          () float64       Σ λ_ij σ_ij² over contacts (1 up to round-off)
solver                      () str           backend name
route                       () str           "lp" or "relaxed" (`calippso.routes`)
phi_input                   () float64       φ of the input
displacement_max            () float64       largest distance of a particle from the input
displacement_median         () float64       median distance (both in mean input diameters)
history_<column>            (records,)       one entry per stage, see `HISTORY_COLUMNS`
==========================  ===============  ===============================================

A run with a deformable box (``jam(..., box="deformable")``) adds, and a sheared box adds
``box_matrix``:

==========================  ===============  ===============================================
box_mode                    () str           "deformable" (absent: "fixed")
stress                      (d, d) float64   contact stress Σ f |r| n nᵀ / V
category                    () str           jamming category of the final packing
box_matrix                  (d, d) float64   box vectors as columns, upper triangular
==========================  ===============  ===============================================

A packing with walls (`calippso.geometry.boundaries`) adds three keys; a periodic one has none of
them, and a file without them is periodic:

==========================  ===============  ===============================================
boundaries                  () str           the kind of every axis, e.g. "walls periodic"
wall_contacts               (K, 2) int64     (particle, wall) of each wall contact; wall
                                             2μ is at 0 on axis μ, 2μ + 1 at L_μ
wall_forces                 (K,) float64     their force magnitudes, in the units of forces
==========================  ===============  ===============================================

Files written before `stop_reason` and `notes` were stored still load: the reason is read
from the status sentence (`calippso.history.reason_from_status`) and the notes are empty.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .atomic import save_npz_atomic
from .history import (HISTORY_COLUMNS, HISTORY_DTYPE, StopReason, empty_history,
                      reason_from_status)
from .geometry.boundaries import axis_name
from .geometry.packing import Packing, packing_of
from .geometry.touching import TOUCHING_GAP, Touching

__all__ = ["JammingResult", "load_result", "HISTORY_COLUMNS", "empty_history", "StopReason"]

#: Separator of the notes in the stored ``notes`` string (no note holds a newline).
_NOTES_SEPARATOR = "\n"


@dataclass(eq=False)
class JammingResult:
    """The jammed packing, its contact network and forces, and how the run went.

    Attributes
    ----------
    packing : Packing
        The final packing (wrapped into the box), with no overlap.
    contacts : ndarray, shape (M, 2), int64
        Contact pairs (i < j) among stable (non-rattler) particles.
    forces : ndarray, shape (M,)
        Contact force magnitudes, normalised to mean 1. Force on i from j points along
        −n_ij = −r_ij/|r_ij| (repulsive).
    rattlers : ndarray, shape (N,), bool
        Particles removed recursively for having fewer than d + 1 contacts.
    converged : bool
        The run ended at a jamming point (``stop_reason.jammed``): either an LP met the
        tolerances (√Γ − 1 < tol_gamma and max |s| over non-rattlers < tol_s,
        `StopReason.CONVERGED`), or the Newton stage's certificate proved the jamming point
        of the contact network (`StopReason.CERTIFIED_NEWTON`, `StopReason.NETWORK_FIRST`,
        see `calippso.certification.newton`). A certified run does not check the tolerances: its last
        history record is the Newton stage's own move.
    status : str
        One sentence on how the run ended, for humans: the stop reason, the last step, the
        network, and the notes.
    iterations : int
        Number of LPs solved (including a final force clean-up LP, if one was needed); 0
        when the network-first stage certified the input's own contact network.
    history : ndarray, structured
        One record per LP, plus one per guessed network (network first) and one for the
        Newton stage if it ran; fields are `HISTORY_COLUMNS`. `history["phi"]` is a
        column.
    wall_time : float
        Seconds from the call to `jam` to the verified result.
    force_balance : float
        max over stable particles of |Σ_j f_ij n_ij| / mean force.
    dual_normalization : float
        Σ λ_ij σ_ij² over contacts of the last LP (1 up to round-off).
    solver : str
        The backend that solved the last LP ("none" when no LP was needed).
    stop_reason : StopReason or None
        Why the loop stopped, for programs; None for a result that does not say (made by
        hand, or an old file whose status names no reason).
    notes : list of str
        What the run repaired, retried or tried on the way (each a clause of `status`).
    wall_contacts : ndarray, shape (K, 2), int64
        Contacts of stable particles with the container's walls: (particle, wall), wall 2μ at
        0 and 2μ + 1 at L_μ along axis μ, 2d for a cylinder (`calippso.geometry.walls`); empty in a
        periodic box.
    wall_forces : ndarray, shape (K,)
        Their force magnitudes, in the units of `forces` (all forces together have mean 1);
        the force on the particle points into the container, along +e_μ from the wall at 0,
        towards the cylinder's axis from the cylinder.
    route : str
        How the jamming point was reached (`calippso.routes`): "lp" (the CALiPPSO loop from
        the input) or "relaxed" (from the input relaxed as soft spheres); "" when not known.
    phi_input : float
        φ of the input (NaN when not known); `phi_change` is φ_J − φ_input.
    displacement_max, displacement_median : float
        Largest and median distance of a particle from its place in the input (minimum
        image, the common translation along periodic axes taken out), in mean diameters of
        the input; NaN when not known.
    box_mode : str
        "fixed" (the box stayed as given) or "deformable" (`calippso.deformable`: the box's
        strain was in every LP; `isostatic` then counts strictly, docs/theory.md).
    stress : ndarray, shape (d, d), or None
        The contact stress tensor Σ_k f_k |r_k| n_k n_kᵀ / V (forces of mean 1, per unit
        volume of the caller's length units) that a deformable run certified; None otherwise
        (`contact_stress` computes it for any periodic result). Isotropic at a strictly
        jammed point (`stress_anisotropy`).
    category : str or None
        The jamming category (`calippso.jamming_category`) of the final packing: found by a
        deformable run ("strict" when it converged) or by ``calippso jam --category``;
        None when not tested.
    """

    packing: Packing
    contacts: np.ndarray
    forces: np.ndarray
    rattlers: np.ndarray
    converged: bool
    status: str
    iterations: int
    history: np.ndarray = field(default_factory=empty_history)
    wall_time: float = 0.0
    force_balance: float = float("nan")
    dual_normalization: float = float("nan")
    solver: str = ""
    stop_reason: StopReason | None = None
    notes: list[str] = field(default_factory=list)
    wall_contacts: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    wall_forces: np.ndarray = field(default_factory=lambda: np.zeros(0))
    route: str = ""
    phi_input: float = float("nan")
    displacement_max: float = float("nan")
    displacement_median: float = float("nan")
    box_mode: str = "fixed"
    stress: np.ndarray | None = None
    category: str | None = None

    @property
    def d(self) -> int:
        """Dimension."""
        return self.packing.d

    @property
    def phi(self) -> float:
        """Jamming packing fraction φ_J."""
        return self.packing.phi

    @property
    def phi_change(self) -> float:
        """φ_J − φ of the input (NaN when the input's φ is not known)."""
        return self.phi - self.phi_input

    @property
    def n_stable(self) -> int:
        """Number of stable (non-rattler) particles N_s."""
        return int(self.packing.n - np.count_nonzero(self.rattlers))

    @property
    def n_contacts(self) -> int:
        """Number of contacts N_c of stable particles: with each other and with walls."""
        return int(self.contacts.shape[0] + self.wall_contacts.shape[0])

    @property
    def n_wall_contacts(self) -> int:
        """Number of contacts with walls (included in `n_contacts`)."""
        return int(self.wall_contacts.shape[0])

    @property
    def isostaticity_gap(self) -> int:
        """N_c − (d N_s + 1 − zero modes): zero for an isostatic packing. The zero modes are
        the d translations in a periodic box (N_c − d (N_s − 1) − 1), the translations along
        the periodic axes with walls (`Boundaries.zero_modes`)."""
        from .geometry.contacts import isostaticity_gap

        boundaries = self.packing.boundaries
        zero_modes = boundaries.zero_modes
        if self.box_mode == "deformable":   # the periodic axes' shape, at fixed volume
            zero_modes -= boundaries.n_periodic * (boundaries.n_periodic + 1) // 2 - 1
        return isostaticity_gap(self.n_contacts, self.n_stable, self.d, zero_modes)

    @property
    def isostatic(self) -> bool:
        """True when the isostaticity gap is zero with at least one stable particle (for a
        deformable run, the strict count N_c = d (N_s − 1) + d(d+1)/2)."""
        return self.n_stable > 0 and self.isostaticity_gap == 0

    @property
    def wall_loads(self) -> np.ndarray:
        """The force of the particles on every wall, along its axis, shape (d, 2).

        Entry (μ, 0) is for the wall at 0 (≤ 0: pushed out of the box), (μ, 1) for the wall
        at L_μ (≥ 0); zeros for an axis without walls. In force balance the two entries of a
        row are equal and opposite. Units of `forces`.
        """
        from .geometry.walls import wall_loads

        return wall_loads(self.d, self.wall_contacts[:, 1], self.wall_forces)

    @property
    def wall_pressures(self) -> np.ndarray:
        """Pressure on every wall, |load| / its area Π_{ν≠μ} L_ν, shape (d, 2) (units of
        `forces` per length^(d−1)); NaN for an axis without walls."""
        box = self.packing.box
        areas = np.prod(box) / box
        pressures = np.abs(self.wall_loads) / areas[:, None]
        walled = np.zeros(self.d, dtype=bool)
        walled[list(self.packing.boundaries.wall_axes)] = True
        pressures[~walled] = np.nan
        return pressures

    @property
    def cylinder_load(self) -> float:
        """The total outward force of the particles on the cylinder (the sum of its contact
        forces, units of `forces`); NaN without a cylinder."""
        if not self.packing.boundaries.cylinder_axes:
            return float("nan")
        from .geometry.walls import cylinder_load

        return cylinder_load(self.d, self.wall_contacts[:, 1], self.wall_forces)

    @property
    def cylinder_pressure(self) -> float:
        """Pressure on the cylinder: `cylinder_load` / its area π L Π_periodic L_ν (units of
        `forces` per length^(d−1)); NaN without a cylinder."""
        boundaries = self.packing.boundaries
        if not boundaries.cylinder_axes:
            return float("nan")
        box = self.packing.box
        area = np.pi * box[boundaries.cylinder_axes[0]] * np.prod(box[boundaries.periodic])
        return self.cylinder_load / float(area)

    @property
    def contact_stress(self) -> np.ndarray | None:
        """The contact stress tensor Σ_k f_k |r_k| n_k n_kᵀ / V, shape (d, d) (forces of
        mean 1, per unit volume): `stress` when the run set it, otherwise computed from
        `contacts` and `forces` in a periodic box (`calippso.geometry.contacts.contact_stress`).
        None in a container (the walls carry part of the load) or without one force per
        contact."""
        if self.stress is not None:
            return self.stress
        if (not self.packing.boundaries.is_periodic or not self.contacts.shape[0]
                or self.forces.shape[0] != self.contacts.shape[0]):
            return None
        from .geometry.contacts import contact_stress

        return contact_stress(self.contact_vectors, self.forces, self.packing.volume)

    @property
    def pressure(self) -> float:
        """The virial pressure of the contact forces: tr(`contact_stress`)/d, over the
        periodic axes in a container (a deformable run's; the walls carry the rest); NaN
        without a stress."""
        return self._stress_reading[0]

    @property
    def stress_anisotropy(self) -> float:
        """max |stress − p I| / p of `contact_stress` (of its periodic axes in a container):
        zero up to round-off at a strictly jammed point, a few per cent at a jamming point
        of a fixed box (N = 1024); NaN without a stress."""
        return self._stress_reading[1]

    @property
    def _stress_reading(self) -> tuple[float, float]:
        """(pressure, anisotropy) of `contact_stress` on the periodic axes
        (`calippso.geometry.contacts.stress_reading`); NaN without a stress."""
        from .geometry.contacts import stress_reading

        stress = self.contact_stress
        if stress is None:
            return float("nan"), float("nan")
        return stress_reading(stress, self.packing.periodic)

    @property
    def rattler_fraction(self) -> float:
        """Fraction of particles that are rattlers."""
        return float(np.count_nonzero(self.rattlers)) / self.packing.n

    @property
    def touching(self) -> "Touching":
        """Pairs that touch outside the contact network (relative gap at most
        `calippso.geometry.touching.TOUCHING_GAP`): stable pairs and particle–wall pairs that carry
        zero force in the certificate (`calippso.geometry.touching`). Counted as contacts, they would
        raise the isostaticity gap by their number."""
        from .geometry.touching import touching_outside_network

        return touching_outside_network(self.packing, self.contacts, self.rattlers,
                                        self.wall_contacts)

    @property
    def touching_pairs(self) -> np.ndarray:
        """Pairs of stable particles (i < j) that touch outside `contacts`, shape (K, 2),
        int64 (`touching`); empty for a packing without degenerate contacts."""
        return self.touching.pairs

    @property
    def contact_numbers(self) -> np.ndarray:
        """Contacts per particle, wall contacts included, shape (N,), int64 (0 for
        rattlers)."""
        every = np.concatenate([self.contacts.ravel(), self.wall_contacts[:, 0]])
        return np.bincount(every, minlength=self.packing.n).astype(np.int64)

    @property
    def contact_vectors(self) -> np.ndarray:
        """Minimum-image r_i − r_j for every contact, shape (M, d)."""
        i, j = self.contacts[:, 0], self.contacts[:, 1]
        return self.packing.minimum_image(self.packing.positions[i] - self.packing.positions[j])

    def summary(self) -> str:
        """A few lines describing the result, for humans."""
        lines = [
            f"{self.status}",
            f"  N = {self.packing.n}, d = {self.d}, phi_J = {self.phi:.10f}",
            f"  LPs = {self.iterations}, wall time = {self.wall_time:.2f} s, solver = {self.solver}",
            f"  stable = {self.n_stable}, rattlers = {self.packing.n - self.n_stable} "
            f"({100 * self.rattler_fraction:.2f} %)",
            f"  contacts = {self.n_contacts}, isostaticity gap = {self.isostaticity_gap} "
            f"({'isostatic' if self.isostatic else 'NOT isostatic'})",
            f"  force balance = {self.force_balance:.2e}, sum lambda sigma^2 = "
            f"{self.dual_normalization:.15f}",
        ]
        if not self.packing.boundaries.is_periodic:
            loads = [f"{axis_name(axis)}: {self.wall_loads[axis, 1]:.6g}"
                     for axis in self.packing.boundaries.wall_axes]
            if self.packing.boundaries.cylinder_axes:
                loads.append(f"cylinder: {self.cylinder_load:.6g}")
            lines.append(f"  {self.packing.boundaries.describe()}; {self.n_wall_contacts} wall "
                         f"contacts; force on the walls {', '.join(loads)}")
        touching = self.touching
        if len(touching):
            walls = (f" and {touching.walls.shape[0]} particle-wall pair(s)"
                     if touching.walls.shape[0] else "")
            lines.append(f"  touching outside the network: {touching.pairs.shape[0]} pair(s) "
                         f"of stable particles{walls} (gap <= {TOUCHING_GAP:g}), zero force "
                         f"in the certificate; counted as contacts the isostaticity gap "
                         f"would be {self.isostaticity_gap + len(touching):+d}")
        category = "not tested" if self.category is None else self.category
        stress = self.contact_stress
        if stress is None:
            lines.append(f"  box = {self.box_mode}; category = {category}")
        else:
            lines.append(f"  box = {self.box_mode}; category = {category}; pressure = "
                         f"{self.pressure:.6g}, stress anisotropy = "
                         f"{self.stress_anisotropy:.1e}; stress = "
                         f"{np.array2string(stress, precision=6, separator=', ')}"
                         .replace("\n", ""))
        if self.route:
            lines.append(f"  route = {self.route}; from the input: max displacement = "
                         f"{self.displacement_max:.2e}, median = "
                         f"{self.displacement_median:.2e} (mean diameters), phi change = "
                         f"{self.phi_change:+.2e}")
        if self.history.shape[0]:
            lines.append(f"  min gap = {self.history['min_gap'][-1]:.2e} (relative to sigma_ij)")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return (f"JammingResult(n={self.packing.n}, d={self.d}, phi={self.phi:.8f}, "
                f"contacts={self.n_contacts}, stable={self.n_stable}, "
                f"isostatic={self.isostatic}, converged={self.converged}, "
                f"iterations={self.iterations})")

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Everything as a flat mapping of arrays (the `.npz` keys documented in this module)."""
        arrays = {
            "positions": self.packing.positions,
            "diameters": self.packing.diameters,
            "box": self.packing.box,
            "contacts": self.contacts,
            "forces": self.forces,
            "rattlers": self.rattlers,
            "converged": np.array(self.converged),
            "iterations": np.array(self.iterations, dtype=np.int64),
            "status": np.array(self.status),
            "wall_time": np.array(self.wall_time),
            "force_balance": np.array(self.force_balance),
            "dual_normalization": np.array(self.dual_normalization),
            "solver": np.array(self.solver),
            "stop_reason": np.array("" if self.stop_reason is None else self.stop_reason.value),
            "notes": np.array(_NOTES_SEPARATOR.join(self.notes)),
            "route": np.array(self.route),
            "phi_input": np.array(self.phi_input),
            "displacement_max": np.array(self.displacement_max),
            "displacement_median": np.array(self.displacement_median),
        }
        if self.packing.box_matrix is not None:
            arrays["box_matrix"] = self.packing.box_matrix
        if self.box_mode != "fixed":
            arrays["box_mode"] = np.array(self.box_mode)
        if self.stress is not None:
            arrays["stress"] = self.stress
        if self.category is not None:
            arrays["category"] = np.array(self.category)
        if not self.packing.boundaries.is_periodic:
            arrays.update(boundaries=np.array(str(self.packing.boundaries)),
                          wall_contacts=self.wall_contacts, wall_forces=self.wall_forces)
        for name in HISTORY_COLUMNS:
            arrays[f"history_{name}"] = self.history[name]
        return arrays

    def save(self, path: str | os.PathLike) -> Path:
        """Write the result to an `.npz` file, atomically (a crash never leaves half a file).

        Returns
        -------
        Path
            The path written (".npz" is appended if missing).
        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        save_npz_atomic(path, self.to_arrays())
        return path

    @classmethod
    def from_arrays(cls, arrays) -> "JammingResult":
        """Rebuild a result from the mapping written by `to_arrays` (e.g. an open `.npz`)."""
        missing = [k for k in ("positions", "diameters", "box", "contacts", "forces", "rattlers")
                   if k not in arrays]
        if missing:
            raise ValueError(f"not a calippso result file: missing keys {missing}")
        records = len(arrays["history_wall_time"]) if "history_wall_time" in arrays else 0
        history = np.zeros(records, dtype=HISTORY_DTYPE)
        for name in HISTORY_COLUMNS:
            key = f"history_{name}"
            if key in arrays:
                history[name] = arrays[key]

        def scalar(key, default, kind):
            return kind(arrays[key][()]) if key in arrays else default

        status = scalar("status", "", str)
        stored_reason = scalar("stop_reason", "", str)
        if stored_reason:
            stop_reason = StopReason(stored_reason)
        else:
            steps = [stage for stage in history["stage"] if stage != "cleanup"]
            stop_reason = reason_from_status(status, steps[-1] if steps else "")
        notes = scalar("notes", "", str)
        return cls(
            packing=packing_of(arrays),
            contacts=np.asarray(arrays["contacts"], dtype=np.int64).reshape(-1, 2),
            forces=np.asarray(arrays["forces"], dtype=np.float64),
            rattlers=np.asarray(arrays["rattlers"], dtype=bool),
            converged=scalar("converged", False, bool),
            status=status,
            iterations=scalar("iterations", 0, int),
            history=history,
            wall_time=scalar("wall_time", float("nan"), float),
            force_balance=scalar("force_balance", float("nan"), float),
            dual_normalization=scalar("dual_normalization", float("nan"), float),
            solver=scalar("solver", "", str),
            stop_reason=stop_reason,
            notes=notes.split(_NOTES_SEPARATOR) if notes else [],
            wall_contacts=np.asarray(arrays.get("wall_contacts", np.zeros((0, 2))),
                                     dtype=np.int64).reshape(-1, 2),
            wall_forces=np.asarray(arrays.get("wall_forces", np.zeros(0)), dtype=np.float64),
            route=scalar("route", "", str),
            phi_input=scalar("phi_input", float("nan"), float),
            displacement_max=scalar("displacement_max", float("nan"), float),
            displacement_median=scalar("displacement_median", float("nan"), float),
            box_mode=scalar("box_mode", "fixed", str),
            category=scalar("category", None, str),
            stress=(np.asarray(arrays["stress"], dtype=np.float64) if "stress" in arrays
                    else None),
        )


def load_result(path: str | os.PathLike) -> JammingResult:
    """Read a `JammingResult` written by `JammingResult.save`.

    Raises ValueError, one line naming the file, if it is not a `.npz` archive.
    """
    from .io.npz import load_arrays

    arrays = load_arrays(path)
    try:
        return JammingResult.from_arrays(arrays)
    except ValueError as error:
        raise ValueError(f"{path}: {error}") from None
