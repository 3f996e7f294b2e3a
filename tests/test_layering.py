"""The shape of the code: which layer may import what, no import cycles, every package installed.

radarviz has two layers. ``core/`` is the numerics (numpy, scipy, numba): it computes and
returns arrays and dataclasses, and never draws, records, serves or writes files. ``viz_app/``
adapts those results to the CLI, Rerun recordings, the Viser panel, matplotlib figures and Dask
sweeps. Inside ``core`` the estimation engine (``core/filters``) does not know about the
experiments built on it, and ``core/geometry.py`` / ``core/params.py`` are leaves that the rest
of ``core`` builds on.

The rules are the tables below; the tests read every ``.py`` file under ``core/`` and
``viz_app/`` with ``ast`` -- module-level and function-local imports alike, plus
``importlib.import_module("...")`` calls and ``"package.module:function"`` strings (the CLI
imports its figure modules that way) -- and report each breach as ``file:line``.
"""

from __future__ import annotations

import ast
import importlib
import re
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Source folder -> installed package name (pyproject.toml's [tool.setuptools] package-dir). The
# public API, viz_app/api, is the top-level package radarviz; a file belongs to the longest
# folder that holds it.
SOURCE_ROOTS: dict[str, str] = {
    "core": "radarviz.core",
    "viz_app": "radarviz.viz_app",
    "viz_app/api": "radarviz",
}
#: The API is the top of the stack: only the command line builds on it (and it on itself).
API_FOLDER = "viz_app/api"
API_USERS: tuple[str, ...] = ("viz_app/api/", "viz_app/cli/")

# (files under this path, imports they must not make, why). A forbidden name matches itself and
# everything below it: "rerun" forbids "rerun" and "rerun.blueprint", not "radarviz.viz_app.rerun".
FORBIDDEN_IMPORTS: tuple[tuple[str, tuple[str, ...], str], ...] = (
    (
        "core/",
        ("radarviz.viz_app", "rerun", "viser", "matplotlib", "dask", "distributed", "pyarrow"),
        "core is the numerics (numpy/scipy/numba) and knows nothing of the application",
    ),
    (
        "core/filters/",
        ("radarviz.core.experiments",),
        "the estimation engine must not depend on the experiments built on it",
    ),
    (
        "core/filters/",
        ("radarviz.core.metrics", "radarviz.core.tracking", "radarviz.core.scenarios"),
        "the estimation engine sits below the statistics, trackers and scenes built on it",
    ),
    (
        "core/velocity/",
        ("radarviz.core.scenarios", "radarviz.core.experiments"),
        "the velocity estimator sits below the scenes that simulate it",
    ),
    ("core/geometry.py", ("radarviz.core",), "geometry is a leaf of core"),
    ("core/params.py", ("radarviz.core",), "params is a leaf of core"),
    ("core/cores.py", ("radarviz.core",), "cores is a leaf of core"),
    (
        "",
        ("core", "viz_app"),
        "the code installs as radarviz.core / radarviz.viz_app; import those names",
    ),
)

# File I/O that core must not do (it returns results; viz_app writes them). Calls are matched by
# their qualified name after resolving import aliases ("np.save" -> "numpy.save"); a name ending
# in ".*" matches every function of that module.
FILE_IO_CALLS: frozenset[str] = frozenset(
    {
        "open",
        "io.open",
        "os.open",
        "os.fdopen",
        "os.replace",
        "os.rename",
        "os.remove",
        "os.unlink",
        "os.mkdir",
        "os.makedirs",
        "os.rmdir",
        "shutil.*",
        "tempfile.*",
        "pickle.dump",
        "pickle.load",
        "json.dump",
        "json.load",
        "numpy.save",
        "numpy.savez",
        "numpy.savez_compressed",
        "numpy.load",
        "numpy.savetxt",
        "numpy.loadtxt",
        "numpy.genfromtxt",
        "numpy.fromfile",
        "numpy.memmap",
    }
)
# Methods that only a path or a file-backed array has (Path.write_text, ndarray.tofile, ...):
# matched on any receiver, since the receiver's type is not known statically.
FILE_IO_METHODS: frozenset[str] = frozenset(
    {
        "open",
        "read_text",
        "write_text",
        "read_bytes",
        "write_bytes",
        "unlink",
        "mkdir",
        "rmdir",
        "rename",
        "touch",
        "tofile",
    }
)
FILE_IO_SCOPE = "core/"

# "radarviz.viz_app.figures.prosov:plot_prosov": a module named in a string, imported later.
_MODULE_FUNCTION = re.compile(r"radarviz(?:\.\w+)+:\w+")


@dataclass(frozen=True)
class Import:
    """One import statement (or string import target) of a project file."""

    file: str  # path relative to the repository root, e.g. "core/filters/cv.py"
    line: int
    target: str  # the imported module as resolved (see ``_resolve``)


# Project module -> {project module it imports: the first import statement making that edge}.
Graph = dict[str, dict[str, Import]]


def _root_of(rel: Path) -> str:
    """The source folder of a file: the longest ``SOURCE_ROOTS`` folder that holds it."""
    posix = rel.as_posix()
    return max((f for f in SOURCE_ROOTS if posix.startswith(f + "/")), key=len)


def _module_name(rel: Path) -> str:
    """Installed dotted name of a source file: core/params.py -> radarviz.core.params,
    viz_app/api/tracking.py -> radarviz.tracking."""
    root = _root_of(rel)
    parts = [SOURCE_ROOTS[root], *rel.with_suffix("").parts[len(Path(root).parts) :]]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


@cache
def _sources() -> dict[str, tuple[str, ast.Module]]:
    """Every project file: relative path -> (module name, parsed tree)."""
    out: dict[str, tuple[str, ast.Module]] = {}
    for folder in SOURCE_ROOTS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if rel.as_posix() in out:  # a nested root (viz_app/api) is walked twice
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(rel))
            out[rel.as_posix()] = (_module_name(rel), tree)
    return out


@cache
def _project_modules() -> dict[str, str]:
    """Module name -> relative path, for every project module (packages included)."""
    return {name: rel for rel, (name, _) in _sources().items()}


def _resolve(module: str, name: str | None) -> str:
    """The module that ``from module import name`` loads: module.name if that is a project
    module file (or package), else module itself (the name is an attribute of it)."""
    if name is not None and f"{module}.{name}" in _project_modules():
        return f"{module}.{name}"
    return module


def _absolute(node: ast.ImportFrom, module_name: str, is_package: bool) -> str:
    """The absolute module of a (possibly relative) ``from ... import``."""
    if not node.level:
        return node.module or ""
    base = module_name.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def _imports_of(rel: str) -> Iterator[Import]:
    module_name, tree = _sources()[rel]
    is_package = rel.endswith("__init__.py")
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield Import(rel, node.lineno, alias.name)
        elif isinstance(node, ast.ImportFrom):
            module = _absolute(node, module_name, is_package)
            for alias in node.names:
                yield Import(rel, node.lineno, _resolve(module, alias.name))
        elif (
            isinstance(node, ast.Call)
            and _call_name(node, {}) in {"importlib.import_module", "import_module", "__import__"}
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            yield Import(rel, node.lineno, node.args[0].value)
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and _MODULE_FUNCTION.fullmatch(node.value)
        ):
            yield Import(rel, node.lineno, node.value.split(":")[0])


def _all_imports() -> list[Import]:
    return [imp for rel in _sources() for imp in _imports_of(rel)]


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _dotted(node: ast.expr) -> str | None:
    """``a.b.c`` of an attribute chain on a plain name, else None."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        head = _dotted(node.value)
        return None if head is None else f"{head}.{node.attr}"
    return None


def _aliases(tree: ast.Module) -> dict[str, str]:
    """Local name -> qualified name bound by the file's imports (any scope)."""
    names: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.asname:
                    names[alias.asname] = alias.name
                else:
                    top = alias.name.split(".")[0]
                    names[top] = top
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for alias in node.names:
                names[alias.asname or alias.name] = f"{node.module}.{alias.name}"
    return names


def _call_name(node: ast.Call, aliases: dict[str, str]) -> str | None:
    """Qualified name of the called function, with import aliases expanded."""
    dotted = _dotted(node.func)
    if dotted is None:
        return None
    head, _, rest = dotted.partition(".")
    head = aliases.get(head, head)
    return f"{head}.{rest}" if rest else head


def _is_file_io(qualified: str | None) -> bool:
    if qualified is None:
        return False
    module = qualified.rpartition(".")[0]
    return qualified in FILE_IO_CALLS or f"{module}.*" in FILE_IO_CALLS


def test_sources_are_found() -> None:
    """The walk sees the tree it guards (a wrong ROOT would make every rule pass vacuously)."""
    modules = _project_modules()
    for expected in (
        "radarviz.core.params",
        "radarviz.core.filters.state",
        "radarviz.viz_app.cli",
        "radarviz",
        "radarviz.tracking",
    ):
        assert expected in modules, f"{expected} not found under {ROOT}"
    assert "radarviz.viz_app.api" not in modules, "viz_app/api must map to radarviz"
    assert any(imp.target == "rerun" for imp in _all_imports()), "no 'import rerun' seen"


def test_the_api_has_one_module_identity() -> None:
    """viz_app/api is radarviz; importing it under radarviz.viz_app.api is refused (a second copy
    of every module would make isinstance checks and test patches silently miss)."""
    import radarviz

    assert radarviz.__name__ == "radarviz"
    with pytest.raises(ImportError, match="import radarviz instead"):
        importlib.import_module("radarviz.viz_app.api")


def test_forbidden_imports() -> None:
    breaches = [
        f"{imp.file}:{imp.line}: imports {imp.target} ({why})"
        for imp in _all_imports()
        for scope, forbidden, why in FORBIDDEN_IMPORTS
        if imp.file.startswith(scope) and any(_within(imp.target, f) for f in forbidden)
    ]
    assert not breaches, "forbidden imports:\n" + "\n".join(breaches)


def _api_modules() -> set[str]:
    return {name for rel, (name, _) in _sources().items() if rel.startswith(API_FOLDER + "/")}


def test_only_the_cli_builds_on_the_api() -> None:
    """The API (viz_app/api, installed as radarviz) sits on top of core and viz_app: core and
    the adapters never import it, so it can call them without a cycle; the CLI goes through
    it."""
    api = _api_modules()
    assert "radarviz" in api and len(api) > 1, api
    breaches = [
        f"{imp.file}:{imp.line}: imports {imp.target} (the API; only {API_USERS} may)"
        for imp in _all_imports()
        if imp.target in api and not imp.file.startswith(API_USERS)
    ]
    assert not breaches, "imports of the API from below it:\n" + "\n".join(breaches)
    cli = {imp.target for imp in _all_imports() if imp.file.startswith("viz_app/cli/")}
    assert cli & api, "the command line does not use the API"


def test_core_does_no_file_io() -> None:
    breaches: list[tuple[str, int, str]] = []
    for rel, (_, tree) in _sources().items():
        if not rel.startswith(FILE_IO_SCOPE):
            continue
        aliases = _aliases(tree)
        for node in ast.walk(tree):
            if not isinstance(node, ast.Call):
                continue
            qualified = _call_name(node, aliases)
            method = node.func.attr if isinstance(node.func, ast.Attribute) else None
            if _is_file_io(qualified) or method in FILE_IO_METHODS:
                shown = qualified or f"<expr>.{method}"
                breaches.append((rel, node.lineno, f"calls {shown}(...)"))
    assert not breaches, (
        "core does no file I/O (it returns results; viz_app/io writes them):\n"
        + "\n".join(f"{rel}:{line}: {what}" for rel, line, what in sorted(breaches))
    )


def _import_graph() -> Graph:
    """Project module -> {imported project module: the first import statement making the edge}.

    Only the named module is an edge: importing a.b.c also runs a/__init__.py and
    a/b/__init__.py, but a package that imports its own submodules is not a cycle."""
    modules = _project_modules()
    graph: Graph = {name: {} for name in modules}
    for imp in _all_imports():
        if imp.target in modules:
            source = _sources()[imp.file][0]
            graph[source].setdefault(imp.target, imp)
    return graph


def _strongly_connected(graph: Graph) -> list[list[str]]:
    """Tarjan's strongly connected components, each a sorted list of module names."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return components


def _cycle_through(start: str, members: set[str], graph: Graph) -> list[Import]:
    """A shortest import path start -> ... -> start inside one component (breadth first)."""
    previous: dict[str, tuple[str, Import]] = {}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w, imp in sorted(graph[v].items()):
                if w not in members or w in previous:
                    continue
                previous[w] = (v, imp)
                if w == start:
                    path, node = [], start
                    while True:
                        v_prev, edge = previous[node]
                        path.append(edge)
                        node = v_prev
                        if node == start:
                            return path[::-1]
                following.append(w)
        frontier = following
    return []


def test_no_import_cycles() -> None:
    graph = _import_graph()
    cycles = []
    for component in _strongly_connected(graph):
        if len(component) == 1 and component[0] not in graph[component[0]]:
            continue
        path = _cycle_through(component[0], set(component), graph)
        steps = "\n".join(f"    {e.file}:{e.line} imports {e.target}" for e in path)
        cycles.append(f"  {' <-> '.join(component)}:\n{steps}")
    assert not cycles, "import cycles among the project's modules:\n" + "\n".join(cycles)


def test_every_package_is_installed() -> None:
    """Each folder of .py files is a package, and pyproject.toml lists each package to install
    (setuptools installs only the listed ones: a missing entry works in the editable checkout
    and fails from a wheel)."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    setuptools = config["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    # The folder of the top-level modules (the console script's entry, outside the package):
    # its files are modules of their own, each listed in py-modules.
    modules_dir = ROOT / setuptools["package-dir"][""]
    problems: list[str] = []
    found: set[str] = set()
    for path in sorted(modules_dir.glob("*.py")):
        if path.stem not in setuptools["py-modules"]:
            problems.append(f"pyproject.toml [tool.setuptools] py-modules lacks {path.stem!r}")
    for folder in SOURCE_ROOTS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            package_dir = path.parent
            if package_dir == modules_dir:
                continue
            rel = package_dir.relative_to(ROOT)
            if not (package_dir / "__init__.py").exists():
                problems.append(f"{rel.as_posix()}/ has .py files but no __init__.py")
                continue
            found.add(_module_name(rel / "__init__.py"))
    problems += [
        f"pyproject.toml [tool.setuptools] packages lacks {name!r}"
        for name in sorted(found - listed)
    ]
    problems += [
        f"pyproject.toml [tool.setuptools] packages lists {name!r}, which has no folder"
        for name in sorted(listed - found)
    ]
    assert not problems, "\n".join(sorted(set(problems)))
