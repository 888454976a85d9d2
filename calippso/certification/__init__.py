"""Certifying a contact network: guess it, settle it, solve it, repair it, check it.

The path of a near-jammed input to its certified jamming point, read top-down. The loop's
stages call it (`calippso.stages.network_first_stage` before any LP,
`calippso.stages.newton_stage` after an LP); geometry (packing, boundaries, neighbours,
contacts, rattlers) lies below it, and the LP with its solvers beside it.

1. **Guess** the candidate networks from the gaps: `network_guess` (periodic box),
   `container_guess` (flat walls, a cylinder).
2. **Settle** which candidate contacts stay closed: `restricted_lp` (the LP restricted to the
   candidate pairs, in the space of their self-stresses).
3. **Solve** the chosen network's jamming point by Newton's method: `newton` (fixed box),
   `strict_newton` (deformable box), on the sparse LU of `sparse_lu`.
4. **Repair** a network a few contacts off: `pivots` (contact pivots on the exact geometry).
5. **Certify**: positive forces, no other overlap, isostatic, force balance
   (`certificate`); in a deformable box, strict jamming and the last LP's strain
   certificate (`strict_certificate`).

`network_first` runs steps 1–4 in rounds on an input's own network, with no LP.
"""
