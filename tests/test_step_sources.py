"""Each estimation step written once: every function of ``core/`` that implements a step kind
is the kind's one plain-arithmetic implementation, or is built on it.

A step kind is declared by the pattern its function names follow and by the functions that
implement it (``core/filters/predict.py``: numbers or arrays alike, compiled by the kernels,
called by the numpy engine and the array-API path). The test reads every function of
``core/`` with ``ast`` and follows calls, including a kernel module's compiled aliases
(``_predict_2d = _inline(predict_2d)``): a function whose name matches a kind must reach one
of its implementations, so a second hand-written prediction (a kernel's own F P Fᵀ, a "fast
path" re-deriving Q) fails here, naming its file. The update kinds (position, EKF, UKF,
Doppler, the IMM's mixing and combination) are not yet written once
(docs/architecture.md, section 3) and are not listed.
"""

from __future__ import annotations

import ast
import re
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class StepKind:
    """A kind of step: the names its functions carry, its implementations ("file:function")
    and the functions whose name matches without implementing it (with why)."""

    pattern: str
    implementations: frozenset[str]
    not_this_step: dict[str, str] = field(default_factory=dict)


STEP_KINDS: dict[str, StepKind] = {
    "constant-velocity prediction": StepKind(
        pattern=r"predict",
        implementations=frozenset(
            {
                "core/filters/predict.py:predict_2d",
                "core/filters/predict.py:predict_components",
                "core/filters/predict.py:add_process_noise",
                "core/filters/predict.py:white_acceleration",
                # The coordinated-turn models' F (the IMM's other prediction), its own kind.
                "core/filters/turn.py:turn_predict",
            }
        ),
        not_this_step={
            "core/filters/kernels_imm.py:_predicted": "the IMM's predicted model probabilities",
            "core/filters/methods.py:_predicted": "a method's predicted measurement",
            "core/tracking/compiled.py:_predicted_kernel": "loads a compiled kernel",
            "core/filters/codes.py:reads_prediction": "whether a conversion reads the prediction",
        },
    ),
}


@dataclass
class Function:
    key: str  # "file:function"
    name: str
    calls: set[str]


@cache
def core_functions() -> tuple[tuple[Function, ...], dict[str, str]]:
    """Every function of core/ with the names it calls, and the module-level aliases
    ``name = wrapper(function)`` (a kernel module compiling a plain function)."""
    functions: list[Function] = []
    aliases: dict[str, str] = {}
    for path in sorted((ROOT / "core").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef):
                calls = {
                    c.func.id if isinstance(c.func, ast.Name) else c.func.attr
                    for c in ast.walk(node)
                    if isinstance(c, ast.Call) and isinstance(c.func, ast.Name | ast.Attribute)
                }
                functions.append(Function(f"{rel}:{node.name}", node.name, calls))
        for node in tree.body:
            if (
                isinstance(node, ast.Assign)
                and isinstance(node.value, ast.Call)
                and node.value.args
                and isinstance(node.value.args[0], ast.Name)
            ):
                for target in node.targets:
                    if isinstance(target, ast.Name):
                        aliases[target.id] = node.value.args[0].id
    return tuple(functions), aliases


def built_on(kind: StepKind, functions: tuple[Function, ...], aliases: dict[str, str]) -> set[str]:
    """The names that reach an implementation of ``kind``: its functions, their compiled
    aliases, and every function calling one of those (to a fixed point)."""
    names = {key.split(":")[1] for key in kind.implementations}
    while True:
        grown = names | {a for a, target in aliases.items() if target in names}
        grown |= {f.name for f in functions if f.calls & grown}
        if grown == names:
            return names
        names = grown


def copies(kind: StepKind, functions: tuple[Function, ...], aliases: dict[str, str]) -> list:
    """The functions named like ``kind`` that neither implement it nor call into it."""
    reach = built_on(kind, functions, aliases)
    pattern = re.compile(kind.pattern)
    return [
        f.key
        for f in functions
        if pattern.search(f.name)
        and f.key not in kind.implementations
        and f.key not in kind.not_this_step
        and not (f.calls & reach)
    ]


@pytest.mark.parametrize("kind_name", sorted(STEP_KINDS))
def test_each_implementation_defined_once(kind_name: str) -> None:
    functions, _ = core_functions()
    keys = [f.key for f in functions]
    for impl in STEP_KINDS[kind_name].implementations:
        assert keys.count(impl) == 1, f"{impl}: defined {keys.count(impl)} times"
        name = impl.split(":")[1]
        same = [f.key for f in functions if f.name == name]
        assert same == [impl], f"{name} defined elsewhere too: {same}"


@pytest.mark.parametrize("kind_name", sorted(STEP_KINDS))
def test_every_step_function_is_built_on_the_one_implementation(kind_name: str) -> None:
    kind = STEP_KINDS[kind_name]
    functions, aliases = core_functions()
    found = copies(kind, functions, aliases)
    assert not found, (
        f"{kind_name}: these functions predict without calling its implementation "
        f"({sorted(kind.implementations)}): {found}"
    )
    stale = [key for key in kind.not_this_step if key not in {f.key for f in functions}]
    assert not stale, f"listed as not a {kind_name} but gone: {stale}"


def test_every_engine_reaches_the_prediction() -> None:
    """The numpy engine, the array-API path and the 2D and 3D kernels all predict through
    the one implementation."""
    reach = built_on(STEP_KINDS["constant-velocity prediction"], *core_functions())
    for name in ("cv_predict", "_predict", "predict_s", "predict_3d", "predict_models"):
        assert name in reach, name


def test_a_hand_written_copy_is_found() -> None:
    """The check itself: beside the real functions, a prediction that re-derives F P Fᵀ is
    reported, and a wrapper calling the compiled alias of the implementation is not."""
    kind = STEP_KINDS["constant-velocity prediction"]
    functions, aliases = core_functions()
    fake = (
        Function("core/filters/fast.py:predict_fast", "predict_fast", {"sqrt"}),
        Function("core/filters/fast.py:predict_wrapped", "predict_wrapped", {"_predict_2d"}),
    )
    assert copies(kind, functions + fake, aliases) == ["core/filters/fast.py:predict_fast"]
