"""The registry of LP backends: the one place where a backend is added.

The built-in backends are registered by module path and imported on first use (`get_backend`),
so that listing and checking the names (`backend_names`, the CLI's choices, the check of
``jam``'s ``solver`` and ``fallback_solvers`` in `calippso.solvers.policy.prepare_backends`)
loads no LP library.
"""

from __future__ import annotations

import importlib

from .backend import Backend

__all__ = ["backend_names", "check_backend_name", "get_backend", "register_backend"]

#: Built-in backends: name -> module whose ``BACKEND`` attribute is the `Backend`.
_BUILT_IN = {"highs": "calippso.solvers.highs", "clarabel": "calippso.solvers.clarabel",
             "cvxpy": "calippso.solvers.cvxpy"}

#: name -> the `Backend`, or the module path that defines it until it is first used.
_REGISTRY: dict[str, Backend | str] = dict(_BUILT_IN)


def backend_names() -> tuple[str, ...]:
    """Names of the registered backends, built-in ones first (imports no LP library)."""
    return tuple(_REGISTRY)


def check_backend_name(name: str, role: str = "solver") -> None:
    """Raise ValueError naming `name` and the known backends if `name` is not registered.

    Parameters
    ----------
    name : str
        A backend name given by the user.
    role : str
        What the name was given as, for the message ("solver", "fallback solver").
    """
    if name not in _REGISTRY:
        raise ValueError(f"unknown {role} {name!r}: choose one of {', '.join(_REGISTRY)}")


def get_backend(name: str) -> Backend:
    """The registered backend `name`, its module imported on first use.

    Raises
    ------
    ValueError
        If no backend of that name is registered.
    """
    check_backend_name(name)
    entry = _REGISTRY[name]
    if isinstance(entry, str):
        entry = importlib.import_module(entry).BACKEND
        _REGISTRY[name] = entry
    return entry


def register_backend(backend: Backend, *, replace: bool = False) -> None:
    """Make `backend` available as ``jam(..., solver=backend.name)`` and in the CLI.

    Parameters
    ----------
    backend : Backend
        An object with ``name``, ``options_type``, ``options``, ``validate`` and ``solve``
        (see `Backend`).
    replace : bool
        Allow replacing a registered backend of the same name.

    Raises
    ------
    TypeError
        If `backend` lacks a member of the `Backend` protocol.
    ValueError
        If the name is taken and `replace` is False.
    """
    if not isinstance(backend, Backend):
        missing = [member for member in ("name", "options_type", "options", "validate", "solve")
                   if not hasattr(backend, member)]
        raise TypeError(f"not an LP backend: {backend!r} lacks {', '.join(missing)}")
    if backend.name in _REGISTRY and not replace:
        raise ValueError(f"a backend named {backend.name!r} is already registered "
                         f"(pass replace=True to replace it)")
    _REGISTRY[backend.name] = backend
