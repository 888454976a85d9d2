"""The geometry below the jamming core: a packing and its box, and who touches whom.

`packing` (the `Packing` value: positions, diameters, box, boundaries) and `boundaries`
(periodic axes, flat walls, a cylinder); `periodic` (minimum images, wrapping, lattices) and
`walls` (the wall rows and forces); `neighbors` (pairs within a gap, by cell lists) and
`sheared_search` (the same in a sheared box); `rattlers` (the recursive rattler rule),
`contacts` (contacts, forces, isostaticity and balance from the LP's duals), `touching`
(pairs that touch outside a contact network) and `contact_network` (the `ContactNetwork`
value and the final repairs of its forces). Nothing here imports an LP solver or numba:
the generators stand on these modules too.
"""
