"""The stages of the CALiPPSO loop, one module each; `calippso.ilp.jam` runs them in order.

Every stage is a function of the run (`Run`: settings, box, units, the history and the
solver policy) and the loop's state (`LoopState`, a frozen value) that returns the new state
and what the stage found; each adds its records and notes to the run's history.

- `state`: `Run` and `LoopState`.
- `network_first_stage`: the input's own contact network, certified with no LP
  (`calippso.certification`).
- `lp_step`: one LP (bound, solve, update, re-solve with left-out rows that overlap) and the
  convergence test.
- `strained_step`: the LP step of a deformable box, with the strain columns of
  `calippso.deformable`.
- `wall_kick`: a hypostatic network between walls moved out of its layers.
- `newton_stage`: the Newton certificate of an isostatic network, and contact pivots.
- `strict_newton_stage`: in a deformable box, the strictly jammed point of a network (the
  Newton stage, and the network hint before the first LP).
- `finish`: forces repaired, round-off overlaps shrunk away, the `JammingResult`.
- `strict_finish`: in a deformable box, the forces with an isotropic stress, the stress and
  the strict certificate, the `JammingResult`.
- `strict_forces`: the forces of that finish: in balance (walls included) with a stress
  isotropic on the periodic axes, at the final geometry.
- `saved`: the loop's state in a checkpoint, and back.
"""
