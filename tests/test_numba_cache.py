"""The kernels' numba cache is keyed on every kernel module (``viz_app.numba_cache``)."""

from __future__ import annotations

import ast
import importlib
import subprocess
import sys
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
    "radarviz.viz_app.bench.reference",
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
    assert numba_cache.install()
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


def _imports_numba(path: Path) -> bool:
    """Whether a module imports numba at its top level (not in a function)."""
    for node in ast.parse(path.read_bytes()).body:
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
        if any(n.split(".")[0] == "numba" for n in names):
            return True
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "numba":
            return True
    return False


def _module_name(path: Path) -> str:
    root = next(r for r in numba_cache._ROOTS if path.is_relative_to(r))
    parts = path.relative_to(root).with_suffix("").parts
    return ".".join(("radarviz", root.name, *parts))


def test_the_finder_knows_every_module_that_imports_numba() -> None:
    """``NUMBA_IMPORTERS`` is exactly the package's modules that import numba at their top:
    a new one missing from it would decorate its kernels with numba's own locators."""
    found = {_module_name(p) for p in numba_cache.kernel_sources() if _imports_numba(p)}
    assert found == numba_cache.NUMBA_IMPORTERS


def test_import_radarviz_leaves_numba_until_a_kernel_module() -> None:
    """``import radarviz`` (and the command line's parser) does not import numba; the first
    kernel module imported still gets the radarviz locators, whichever it is."""
    script = """
import sys
import radarviz
from radarviz.viz_app.cli.main import build_parser
build_parser()
assert "numba" not in sys.modules, "numba imported"
import importlib
module = importlib.import_module(sys.argv[1])
kernels = [v for v in vars(module).values() if hasattr(v, "_cache") and hasattr(v, "py_func")]
cached = [k for k in kernels if type(k._cache).__name__ != "NullCache"]
assert cached, "no cached kernel"
names = {type(k._cache._impl.locator).__name__ for k in cached}
assert all(n.startswith("Radarviz") for n in names), names
print(len(cached))
"""
    for name in ("radarviz.core.tracking.kernels_monitor", "radarviz.viz_app.io.csv_text"):
        done = subprocess.run(
            [sys.executable, "-c", script, name], capture_output=True, text=True, check=False
        )
        assert done.returncode == 0, done.stderr
        assert int(done.stdout) >= 1


def test_console_script_help_leaves_numba_and_the_engines() -> None:
    """``radarviz --help`` as the console script runs it (``radarviz_entry.main``, which also
    installs the start-up SIGINT handler) imports neither numba nor the heavy engines: the
    parser alone is checked above, and this is the path a user's ``--help`` takes."""
    script = """
import contextlib, io, sys
sys.argv = ["radarviz", "--help"]
import radarviz_entry
with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.suppress(SystemExit):
    radarviz_entry.main()
assert "usage:" in out.getvalue(), out.getvalue()
heavy = {"numba", "llvmlite", "scipy", "rerun", "viser", "matplotlib", "dask"}
print(sorted(heavy & {m.partition(".")[0] for m in sys.modules}))
"""
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"
