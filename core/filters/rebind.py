"""One step's plain functions, re-bound to another set of elementary functions.

A step written once (``core.filters.position_2d``) calls its helpers and a few elementary
functions (``sqrt``, ``where``) by their module-level names, numpy's by default. Compiled
code needs the scalar ones (``math.sqrt``, a select) and its helpers compiled too: numba
resolves a called name in the function's globals when it compiles it. ``rebind`` makes
copies of the functions that share one globals dictionary, the module's own with
``elementary`` laid over it, wraps each (e.g. in numba's decorator) and puts the wrapped
copies in that dictionary, so each copy calls the others' wrapped copies. The code objects
are the originals: the same source, line for line.
"""

from __future__ import annotations

import types
from collections.abc import Callable, Sequence
from typing import Any


def rebind(
    functions: Sequence[types.FunctionType],
    elementary: dict[str, Any],
    wrap: Callable[[types.FunctionType], Any] = lambda f: f,
) -> dict[str, Any]:
    """``{name: wrap(copy)}`` of ``functions`` (all of one module), the copies calling
    ``elementary``'s objects and one another's wrapped copies by name."""
    shared = dict(functions[0].__globals__)
    shared.update(elementary)
    out = {}
    for f in functions:
        if f.__globals__ is not functions[0].__globals__:
            raise ValueError(f"rebind: {f.__qualname__} is not in {functions[0].__module__}")
        copy = types.FunctionType(f.__code__, shared, f.__name__, f.__defaults__, f.__closure__)
        copy.__qualname__, copy.__module__, copy.__doc__ = f.__qualname__, f.__module__, f.__doc__
        out[f.__name__] = wrap(copy)
    shared.update(out)
    return out


def rebind_modules(
    groups: Sequence[Sequence[types.FunctionType]],
    elementary: dict[str, Any],
    wrap: Callable[[types.FunctionType], Any] = lambda f: f,
    required: Sequence[str] = (),
) -> dict[str, Any]:
    """``rebind`` of each group (one module's functions) in order, every group's copies
    calling the wrapped copies of the groups before it (a step calling another module's
    step by the name it imported) as well as ``elementary``, which must hold every name of
    ``required`` (the elementary functions the steps call)."""
    missing = sorted(set(required) - set(elementary))
    if missing:
        raise ValueError(f"rebind_modules: elementary functions missing: {missing}")
    out: dict[str, Any] = {}
    for functions in groups:
        out.update(rebind(functions, {**elementary, **out}, wrap))
    return out
