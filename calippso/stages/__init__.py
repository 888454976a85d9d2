"""The stages of the CALiPPSO loop, one module each; `calippso.ilp.jam` runs them in order.

Every stage is a function of the run (`Run`: settings, box, units, the history and the
solver policy) and the loop's state (`LoopState`, a frozen value) that returns the new state
and what the stage found; each adds its records and notes to the run's history.

- `state`: `Run` and `LoopState`.
- `network_first_stage`: the input's own contact network, certified with no LP
  (`calippso.certification`).
- `lp_step`: one LP (bound, solve, update, re-solve with left-out rows that overlap) and the
  convergence test.
- `wall_kick`: a hypostatic network between walls moved out of its layers.
- `newton_stage`: the Newton certificate of an isostatic network, and contact pivots.
- `finish`: forces repaired, round-off overlaps shrunk away, the `JammingResult`.
- `saved`: the loop's state in a checkpoint, and back.
"""
