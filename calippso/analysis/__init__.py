"""Analysis of jammed packings: contacts, gaps, forces, bucklers and critical exponents.

Every function takes one `JammingResult` or a sequence of them (an ensemble, pooled; all of
one dimension). Pooling many packings is how exponents are measured in practice.

Modules: `structure` (contact numbers, rattlers, isostaticity), `gaps` (non-contact gaps),
`forces` (bucklers, localised and extended forces), `sample` (pooled values and their
cumulative), `fits` (power-law fits of cumulatives, window rule, bootstrap), `exponents`
(γ, θ_e, θ_ℓ and reference values), `finite_size` (the exponents at each size N and their
limits N → ∞; `extrapolation` holds the correction forms, `collapse` the gap cut-off h_min(N)
and the scaled axes, `resampling` the bootstrap's window sums), `wall_forces` (the forces, loads and pressures on a
container's walls, apart from the particle forces), `layering` (packing fraction against the
distance from the nearest wall; `slices` holds its geometry), `summary` (`analyze`,
everything at once), `record` (`run_record`, the flat description of one run).
"""

from .exponents import (REFERENCE_EXPONENTS, UPPER, Exponent, critical_exponents,
                        exponent_from_sample, window_scan)
from .collapse import GapCutoff, collapsed_cumulative, gap_cutoff
from .extrapolation import Correction, Extrapolation, extrapolate
from .finite_size import (FiniteSizeAnalysis, SizeExponents, finite_size_analysis,
                          packings_needed, sizes_of)
from .fits import PowerLawFit, fit_cumulative_power_law
from .forces import bucklers, localized_contacts, normalized_forces, pooled_forces
from .gaps import DEFAULT_MAX_GAP, gaps, pooled_gaps
from .layering import DensityProfile, density_profile, pooled_density_profile
from .record import RUN_RECORD_KEYS, run_record
from .sample import PooledSample
from .structure import ContactStatistics, contact_statistics
from .summary import Analysis, analyze
from .wall_forces import normalized_wall_forces, pooled_wall_forces, wall_load_rows

__all__ = [
    "Analysis", "ContactStatistics", "DEFAULT_MAX_GAP", "DensityProfile", "Exponent",
    "PooledSample", "density_profile", "normalized_wall_forces", "pooled_density_profile",
    "pooled_wall_forces", "wall_load_rows",
    "PowerLawFit", "REFERENCE_EXPONENTS", "UPPER", "analyze", "bucklers", "contact_statistics",
    "critical_exponents", "exponent_from_sample", "fit_cumulative_power_law", "gaps",
    "localized_contacts", "normalized_forces", "pooled_forces", "pooled_gaps", "RUN_RECORD_KEYS",
    "run_record", "window_scan", "Correction", "Extrapolation", "FiniteSizeAnalysis",
    "GapCutoff", "SizeExponents", "collapsed_cumulative", "extrapolate", "finite_size_analysis",
    "gap_cutoff", "packings_needed", "sizes_of",
]
