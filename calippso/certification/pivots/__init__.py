"""Contact pivots: an active-set path from a network that is a few contacts off to the jammed one.

The start is an isostatic contact network C at its Newton point (`calippso.certification.newton`): the
contact equations |r_c|² = Γ σ_c² hold on C, no other pair of stable particles overlaps,
and the forces y (the self-stress of Jᵀ y = (0, …, 0, −1)) are known, but some are not
positive. The CALiPPSO LP at that point would move on; here the same move is made on the
exact geometry, one contact at a time, as the simplex method moves from vertex to vertex:

1. **Certify.** Every force positive: the point is the jamming point (the caller still runs
   the certificate of `calippso.certification.certificate.certify_network`).
2. **Release** a contact c with y_c ≤ 0 (the most negative one, or the next ones when its
   release gives no pivot; smallest pair key while the path is degenerate, Bland's rule, so
   that it cannot cycle). The network A = C ∖ c, less
   the particles it leaves with only d contacts (rattlers, removed recursively with their
   contacts), has exactly one floppy mode t: J_A t = 0, normalised to dΓ = 1. Along it c
   opens, because y_cᵀ (J_C t)_c = −dΓ, and Γ grows.
3. **Ratio test.** Every pair q of stable particles outside A closes along t at the
   inflation step δ_q = Φ_q / (−∇Φ_q · t), where Φ_q = |r_q|²/σ_q² − Γ. The pair with the
   smallest step closes first; among pairs within round-off of it, the one that closes
   fastest (Harris's ratio test, for a well-conditioned network).
4. **Pivot in.** C' = A ∪ {k} is isostatic again. Newton solves it from the predicted point
   x + δ_k t, which makes the linear ratio test exact: the new vertex is accepted when no
   other pair overlaps there and Γ did not decrease; otherwise the next pair of the ratio
   test is tried. Its forces cost one transposed solve. Repeat from 1.

Rattlers (those of the start, and those a release leaves) carry no force and do not move
with the floppy modes. Their cages enter the ratio test (`cages.closing_cages`): a small LP
per cage finds the step at which its rattlers (one, or a few near one another) no longer
fit; when that comes before the pair of the ratio test, the k rattlers join the network with
the k d + 1 pairs that close on them (k d unknowns and k d + 1 rows: the released network
becomes isostatic again). A rattler whose cage stays open is moved out of the way of the
moved cage (`calippso.geometry.rattlers.separate_rattlers`); when one cannot be, the pivot
is made again with the particles that the release left with d contacts kept in the network,
held by their d contacts.

Γ never decreases, so the path can only revisit a network through degenerate pivots (where
the closing pair already touches); Bland's rule and a record of the networks seen since Γ
last grew rule that out.

One sparse LU (`calippso.certification.sparse_lu`) serves many pivots: a pivot swaps one row of the
Jacobian, and solves with the swapped matrix use the stored factors and the Woodbury
identity (`vertex.Basis`), refined iteratively against the exact matrix; the Jacobian is
factorised again when 40 rows have been swapped, when the refinement does not reach
round-off, or when rattlers change the unknowns.
"""

from .geometry import (MAX_NEAR_GAP, NEAR_GAP, RATIO_CANDIDATES, clear_rattlers,
                       find_closing_pairs, outside_pairs)
from .path import CAGE_CLOSED, MAX_PIVOTS, pivot_to_jamming
from .vertex import DEGENERATE_STEP, PivotPath, Swap, describe_path

__all__ = ["PivotPath", "Swap", "pivot_to_jamming", "describe_path",
           "find_closing_pairs", "outside_pairs",
           "clear_rattlers", "MAX_PIVOTS", "NEAR_GAP", "MAX_NEAR_GAP", "DEGENERATE_STEP",
           "RATIO_CANDIDATES", "CAGE_CLOSED"]
