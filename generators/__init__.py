"""Numba generators of compressed starting configurations (LS, FB, MLS, spherocylinders).

Importing this package never imports an LP solver; the generators return `calippso.Packing`.
"""
