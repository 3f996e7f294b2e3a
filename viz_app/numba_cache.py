"""numba's on-disk cache of radarviz's kernels, keyed on every kernel module's source.

The kernels are compiled with ``cache=True`` so that a command does not spend ~18 s of CPU
compiling them on every start. numba keys a cached function on the source of the file that
defines it, and only that one: a tracker kernel in ``core/filters/kernels_imm.py`` inlines
stage functions of ``kernels_3d.py`` and ``kernels_2d.py``, so after an edit of those (a
checkout, a patch, an editable install's update) the cached machine code would still be the
old one, silently. Here the stamp of every radarviz kernel is instead the hash of all the
package's modules that use numba, so an edit of any of them recompiles them all on their next
use; numba's own locations (its cache directory if set, the module's ``__pycache__``, the
user-wide cache) are kept.

``install`` registers the locators with numba. numba chooses a function's locator when the
function is decorated, so they must be in place before any kernel module runs; but importing
numba costs about a third of a second, which a command that compiles nothing (``--help``,
``view``, ``import radarviz``) should not pay. So importing this module (``radarviz``, the
package, does it first) calls :func:`install_before_kernels`, which imports nothing: it puts
a finder first on ``sys.meta_path`` that, when one of ``NUMBA_IMPORTERS`` (the modules that
import numba themselves; every other kernel module imports one of them first) is about to be
imported, calls ``install`` (which imports numba) and steps aside. If numba is already
imported (a program imported it before radarviz) ``install`` runs at once.
"""

from __future__ import annotations

import functools
import hashlib
import sys
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from pathlib import Path
from types import ModuleType
from typing import Any

#: The package's folders (the installed ``radarviz`` maps them: ``core``, ``viz_app``).
_ROOTS = (Path(__file__).resolve().parent, Path(__file__).resolve().parent.parent / "core")


def kernel_sources(roots: tuple[Path, ...] = _ROOTS) -> list[Path]:
    """The modules under ``roots`` that use numba (sorted): a kernel can only inline what one
    of them defines."""
    found = []
    for root in roots:
        for path in root.rglob("*.py"):
            if b"numba" in path.read_bytes():
                found.append(path)
    return sorted(found)


@functools.cache
def kernels_stamp(roots: tuple[Path, ...] = _ROOTS) -> str:
    """SHA-256 of every kernel module's path (relative to its root) and bytes: the cache stamp
    of every radarviz kernel (module docstring)."""
    digest = hashlib.sha256()
    for path in kernel_sources(roots):
        root = next(r for r in roots if path.is_relative_to(r))
        digest.update(str(path.relative_to(root.parent)).encode())
        digest.update(b"\0")
        digest.update(path.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


def _in_package(py_file: str) -> bool:
    try:
        path = Path(py_file).resolve()
    except OSError:
        return False
    return any(path.is_relative_to(root) for root in _ROOTS)


def _family(base: type) -> type:
    """numba's locator ``base``, for radarviz's files only, stamped with ``kernels_stamp``
    (and, as numba's own, the file's)."""

    class Locator(base):  # type: ignore[misc, valid-type]
        def get_source_stamp(self) -> Any:
            return (super().get_source_stamp(), kernels_stamp())

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            if not _in_package(py_file):
                return None
            return super().from_function(py_func, py_file)

    Locator.__name__ = Locator.__qualname__ = f"Radarviz{base.__name__}"
    return Locator


@functools.cache
def install() -> bool:
    """Put the radarviz locators first in numba's list (once per process); False, and numba's
    own behaviour, when this numba has no such list."""
    try:
        from numba.core import caching
    except ImportError:
        return False
    impl = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
    names = ("UserProvidedCacheLocator", "InTreeCacheLocator", "UserWideCacheLocator")
    bases = [getattr(caching, n, None) or getattr(caching, "_" + n, None) for n in names]
    if impl is None or None in bases or not isinstance(impl._locator_classes, list):
        return False
    impl._locator_classes[:0] = [_family(b) for b in bases]
    return True


#: The package's modules that import numba at their top: each decorates kernels (or is the
#: first import of one that does), so the locators go in before any of them runs.
#: ``tests/test_numba_cache.py`` checks this against the sources.
NUMBA_IMPORTERS = frozenset(
    {
        "radarviz.core.filters.kernels_2d",
        "radarviz.viz_app.io.csv_text",
        "radarviz.viz_app.bench.reference",
    }
)


class _BeforeKernels:
    """A ``sys.meta_path`` finder that finds nothing: on the first import of one of
    ``NUMBA_IMPORTERS`` it installs the locators and removes itself."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        if fullname in NUMBA_IMPORTERS:
            _remove_finder()
            install()
        return None  # the ordinary finders import the module


_FINDER = _BeforeKernels()


def _remove_finder() -> None:
    while _FINDER in sys.meta_path:
        sys.meta_path.remove(_FINDER)


def install_before_kernels() -> None:
    """Have ``install`` run before the first kernel module is imported, without importing
    numba now (module docstring); at once if numba is already imported."""
    if "numba" in sys.modules:
        install()
    elif not install.cache_info().currsize and _FINDER not in sys.meta_path:
        sys.meta_path.insert(0, _FINDER)


install_before_kernels()
