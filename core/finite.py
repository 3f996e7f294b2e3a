"""The one check a computed result passes before anyone prints, writes or shows it.

A Monte Carlo σ, a NEES, a track state or a benchmark time that came out NaN or infinite, or a
NEES, NIS, variance or RMSE that came out negative, is a failure of the computation, not a
number to report. :func:`check_finite_result` raises :class:`ResultError` at the first such
value, naming where it appeared::

    reproduce prosov: nees_pos of ukf at scan 12 is NaN (not a finite result)

Some values are undefined by construction, and those are reported as undefined (``null`` in
JSON, ``-`` in tables), never as failures. Each caller says which with ``defined``, a mask
derived from the structure of the computation and never from the values themselves (so a NaN
where a value must exist always fails):

* a finite-memory fit of k scans estimates min(k·m, 3) of (r, Vr, a) (m = 2 with Doppler,
  else 1; ``core.finite_memory.fit.max_order``): the rest of its σ and gains are undefined;
* a track started from the first k scans has no statistics before scan k;
* a delete-a-group band needs two groups of runs.

This module is pure (no I/O): the command line turns a ``ResultError`` into one line on
standard error and exit status 1 with nothing written; the tuning panel shows it as its error
line and keeps the last good run on screen.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike


class ResultError(ValueError):
    """A computed result is not a number one can report; ``str()`` is one line naming it."""


def _describe(value: float) -> str:
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "+inf" if value > 0 else "-inf"
    return f"{value:.6g}"


def check_finite_result(
    where: str,
    name: str,
    values: ArrayLike,
    *,
    defined: ArrayLike | None = None,
    nonnegative: bool = False,
    index_name: str = "scan",
    index: Sequence[object] | None = None,
) -> None:
    """Raise :class:`ResultError` unless every defined value of ``values`` is a finite number
    (and, with ``nonnegative``, not below zero).

    Args:
        where: the command or panel scene ("reproduce prosov", "tune velocity").
        name: what the values are ("nees_pos of ukf", "x_m of ekf").
        values: any shape; the first axis is the one ``index`` labels.
        defined: boolean mask broadcast to ``values``: where False the value is undefined by
            construction and may be anything (NaN, typically). None: every value is defined.
        nonnegative: a NEES, NIS, variance, σ or RMSE: negative is a failure too.
        index_name, index: how a position is named: "scan 12" is ``index_name`` and
            ``index[i]`` of the first axis (default ``i + 1``); further axes follow in
            brackets ("gain_percent at k 5 [1]").
    """
    a = np.asarray(values, dtype=np.float64)
    bad = ~np.isfinite(a)
    if nonnegative:
        bad |= a < 0  # NaN compares False: already counted above
    if defined is not None:
        bad &= np.broadcast_to(np.asarray(defined, dtype=bool), a.shape)
    if not bad.any():
        return
    pos = np.unravel_index(int(np.argmax(bad)), a.shape) if a.ndim else ()
    value = float(a[pos])
    at = ""
    if pos:
        first = pos[0]
        label = index[first] if index is not None else first + 1
        at = f" at {index_name} {label}"
        if len(pos) > 1:
            at += "".join(f"[{int(p)}]" for p in pos[1:])
    why = (
        "not a finite result"
        if not math.isfinite(value)
        else "a negative value where only values >= 0 are possible"
    )
    raise ResultError(f"{where}: {name}{at} is {_describe(value)} ({why})")


def check_finite_figures(
    where: str, figures: Mapping[str, float], nonnegative: Sequence[str] = ()
) -> None:
    """:func:`check_finite_result` on every entry of a {name: number} mapping (a status
    line's figures). A name in ``nonnegative``, or ending in one of its entries that start with
    "." ("ukf.nees_pos" for ".nees_pos"), must be >= 0."""
    exact = set(nonnegative)
    suffixes = tuple(s for s in nonnegative if s.startswith("."))
    for key, value in figures.items():
        positive = key in exact or key.endswith(suffixes)
        check_finite_result(where, key, value, nonnegative=positive)


def check_finite_document(
    where: str,
    doc: object,
    nonnegative: Sequence[str] | bool = (),
    path: str = "",
    signed: Sequence[str] = (),
) -> None:
    """:func:`check_finite_result` on every number of a JSON-ready document (dicts, lists,
    numbers; strings, booleans and None are not results). A number under a key in
    ``nonnegative`` (True: every number, e.g. a benchmark's times and ratios), and not in
    ``signed`` (a figure that may be below zero, such as a trend's slope), must be >= 0.
    The failing value is named by its path in the document ("baseline.sigma_mc_mps[1]"). For
    documents where nothing is undefined by construction."""
    if isinstance(doc, Mapping):
        for key, value in doc.items():
            at = f"{path}.{key}" if path else key
            check_finite_document(where, value, nonnegative, at, signed)
    elif isinstance(doc, list | tuple):
        for i, value in enumerate(doc):
            check_finite_document(where, value, nonnegative, f"{path}[{i}]", signed)
    elif isinstance(doc, int | float) and not isinstance(doc, bool):
        key = path.split(".")[-1].split("[")[0]
        positive = nonnegative if isinstance(nonnegative, bool) else key in nonnegative
        check_finite_result(where, path, doc, nonnegative=positive and key not in signed)
