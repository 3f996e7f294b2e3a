"""The kernels' numba cache is keyed on every kernel module (``viz_app.numba_cache``)."""

from __future__ import annotations

import importlib
from pathlib import Path

import numba

from radarviz.viz_app import numba_cache

KERNEL_MODULES = (
    "radarviz.core.conversion.elementwise",
    "radarviz.core.filters.compiled",
    "radarviz.core.filters.kernels_2d",
    "radarviz.core.filters.kernels_3d",
    "radarviz.core.filters.kernels_track",
    "radarviz.core.filters.kernels_imm",
    "radarviz.core.tracking.kernels_monitor",
    "radarviz.viz_app.io.csv_text",
    "radarviz.viz_app.bench.scalar_reference",
)


def test_the_stamp_follows_every_kernel_module_and_only_them(tmp_path: Path) -> None:
    core, app = tmp_path / "core", tmp_path / "viz_app"
    (core / "filters").mkdir(parents=True)
    app.mkdir()
    kernel = core / "filters" / "kernels.py"
    other = app / "plain.py"
    kernel.write_text("import numba\n\n@numba.njit(cache=True)\ndef f(x):\n    return x\n")
    other.write_text("def g():\n    return 1\n")
    roots = (app, core)
    stamp = numba_cache.kernels_stamp.__wrapped__
    assert numba_cache.kernel_sources(roots) == [kernel]
    first = stamp(roots)
    other.write_text("def g():\n    return 2\n")  # not a kernel module: the same stamp
    assert stamp(roots) == first
    kernel.write_text(kernel.read_text().replace("return x", "return x + 1"))
    assert stamp(roots) != first
    helper = app / "helper.py"  # a new module that compiles: part of the family
    helper.write_text("from numba import njit\n")
    assert numba_cache.kernel_sources(roots) == [kernel, helper]


def test_every_cached_kernel_of_radarviz_uses_the_family_stamp() -> None:
    assert numba_cache.INSTALLED
    stamp = numba_cache.kernels_stamp()
    seen = 0
    for name in KERNEL_MODULES:
        module = importlib.import_module(name)
        for value in vars(module).values():
            if not isinstance(value, numba.core.registry.CPUDispatcher):
                continue
            if (
                value.__module__ != module.__name__
                or value._cache.__class__.__name__ == "NullCache"
            ):
                continue
            locator = value._cache._impl.locator
            assert type(locator).__name__.startswith("Radarviz"), (name, value)
            assert locator.get_source_stamp()[1] == stamp
            seen += 1
    assert seen >= 30
    # Every module that compiles is in the family the stamp hashes.
    sources = {p.name for p in numba_cache.kernel_sources()}
    assert {n.rsplit(".", 1)[1] + ".py" for n in KERNEL_MODULES} <= sources
