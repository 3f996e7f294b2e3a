"""Each estimation step written once: every function of ``core/`` that implements a step kind
is the kind's one plain-arithmetic implementation, or is built on it.

A step kind is declared by the pattern its function names follow and by the functions that
implement it (``core/filters/predict.py``: numbers or arrays alike, compiled by the kernels,
called by the numpy engine and the array-API path). The test reads every function of
``core/`` with ``ast`` and follows calls, including a kernel module's compiled aliases
(``_predict_2d = _inline(predict_2d)``): a function whose name matches a kind must reach one
of its implementations, so a second hand-written prediction (a kernel's own F P Fᵀ, a "fast
path" re-deriving Q) fails here, naming its file. A kind's copies that are still to be
replaced are listed as such (``not_yet``), and the test holds that list to the tree.
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
    #: copies not yet replaced by the implementation (each with what remains to do); the
    #: test holds the list to the tree, so it can only shrink
    not_yet: dict[str, str] = field(default_factory=dict)


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
            "core/filters/imm_moments.py:predicted_probabilities": (
                "the IMM's predicted model probabilities"
            ),
            "core/filters/methods.py:_predicted": "a method's predicted measurement",
            "core/tracking/compiled.py:_predicted_kernel": "loads a compiled kernel",
            "core/conversion/registry.py:about_prediction": (
                "whether a conversion's covariance is taken at the prediction"
            ),
            "core/filters/methods.py:about_prediction": "the same, of a method",
        },
    ),
    "position update (Joseph form on a factor)": StepKind(
        pattern=r"position_update|joseph",
        implementations=frozenset(
            {
                "core/filters/position_2d.py:position_update_2d",
                "core/filters/position_3d.py:position_update_3d",
                "core/filters/position_3d.py:factored_joseph_3d",
            }
        ),
        not_this_step={
            "core/filters/joseph.py:joseph_update": (
                "the Joseph form for any H, of the converted and the joint Doppler updates "
                "(numpy only, no kernel); its factor is the 2D and 3D one"
            ),
        },
    ),
    "polar EKF update": StepKind(
        pattern=r"ekf_update|ekf_measurement|ekf_pseudo",
        implementations=frozenset(
            {
                "core/filters/ekf_2d.py:ekf_measurement_2d",
                "core/filters/ekf_2d.py:ekf_update_2d",
                "core/filters/ekf_3d.py:ekf_measurement_3d",
            }
        ),
    ),
    "polar UKF update": StepKind(
        pattern=r"ukf_update|_ukf",
        implementations=frozenset(
            {"core/filters/ukf_2d.py:ukf_update_2d", "core/filters/ukf_3d.py:ukf_update_3d"}
        ),
    ),
    "Doppler update along the measured line of sight": StepKind(
        pattern=r"doppler_update",
        implementations=frozenset(
            {
                "core/filters/doppler_2d.py:doppler_update_2d",
                "core/filters/doppler_3d.py:doppler_update_3d",
            }
        ),
        not_this_step={
            "core/filters/converted_doppler.py:converted_doppler_update": (
                "the converted r̂·V̂r measurement, its own kind"
            ),
            "core/filters/joint_doppler.py:joint_doppler_update": (
                "the EKF and the Doppler value as one update, its own kind"
            ),
        },
    ),
    "IMM mixing and combination": StepKind(
        pattern=r"mix|combine",
        implementations=frozenset(
            {
                "core/filters/imm_moments.py:mix_2d",
                "core/filters/imm_moments.py:combine_2d",
                "core/filters/imm_moments.py:mix_3d",
                "core/filters/imm_moments.py:combine_3d",
            }
        ),
        not_this_step={
            "core/conversion/elementwise_3d.py:combined_entries": "a 3D conversion's covariance",
        },
    ),
    "polar-to-Cartesian conversion (2D and 3D)": StepKind(
        pattern=r"convert|_cov$|_cov_|_entries|moments$|noise_table|coefficients|scale",
        implementations=frozenset(
            {
                f"core/conversion/elementwise.py:{name}"
                for name in (
                    "unit_scale",
                    "seed_scale",
                    "debiasing_scale",
                    "unbiasing_scale",
                    "averaged_coefficients",
                    "true_cov_coefficients",
                    "conversion_coefficients",
                    "linearized_entries",
                    "averaged_entries",
                    "true_entries",
                    "converted_point",
                )
            }
            | {
                f"core/conversion/elementwise_3d.py:{name}"
                for name in (
                    "exponentials",
                    "noise_table",
                    "angle_moments",
                    "posterior_moments",
                    "combined_entries",
                    "linearized_entries_3d",
                    "true_entries_3d",
                    "averaged_entries_3d",
                    "converted_point_3d",
                )
            }
        ),
        not_this_step={
            "core/conversion/second_order.py:second_order_cov": (
                "the second-order moments of any map (Prosov's eq. 7), the analysis tool the "
                "seed's scale is derived with"
            ),
            "core/conversion/second_order.py:second_order_convert": "the same tool",
            "core/filters/converted_doppler.py:converted_doppler_moments": (
                "the converted r̂·V̂r measurement, its own kind"
            ),
            "core/filters/converted_doppler.py:converted_doppler_terms": "the same measurement",
            "core/filters/converted_doppler.py:converted_doppler_update": "the same measurement",
            "core/filters/imm_moments.py:_add_scaled": "the IMM's weighted outer products",
            "core/filters/position.py:upper_entries": "a matrix's upper entries as a dict",
            "core/finite_memory/fit.py:_closed_cov": "the finite-memory fit's covariance",
            # These reach a ``*_scale`` implementation as ``Conversion.scale``, an attribute
            # the registry binds, which the call graph below does not follow.
            **{
                key: "calls a registered conversion's scale through the registry"
                for key in (
                    "core/conversion/planar.py:scale_factor",
                    "core/conversion/registry.py:scales",
                    "core/conversion/spatial.py:scale_3d",
                    "core/conversion/spatial.py:ucm_scale_3d",
                    "core/filters/methods.py:scale_table",
                )
            },
        },
    ),
    "innovation statistics (NIS and log det S)": StepKind(
        pattern=r"(position|doppler)_(stats|nis|innovation)|^nis_\d|gaussian_stats|linear_innov",
        implementations=frozenset(
            {
                "core/filters/position_2d.py:position_stats_2d",
                "core/filters/position_3d.py:position_stats_3d",
                "core/filters/doppler_2d.py:doppler_stats_2d",
                "core/filters/doppler_3d.py:doppler_stats_3d",
            }
        ),
        not_this_step={
            "core/filters/innovation.py:gaussian_stats": (
                "any linear measurement's statistics (ν, S given): the converted and the "
                "joint Doppler updates', which have no kernel"
            ),
            "core/filters/innovation.py:linear_innovation": "the same, from H and R",
        },
        not_yet={
            "core/filters/kernels_track.py:position_stats": (
                "the tracker kernels' own 2D statistics: bound to the steps' copy, a target's "
                "IMM results came to depend by rounding on the other targets in its block"
            ),
            "core/filters/kernels_track.py:position_nis": "calls position_stats",
            "core/filters/kernels_track.py:doppler_stats": "as position_stats",
            "core/filters/kernels_track.py:doppler_nis": "calls doppler_stats",
            "core/filters/kernels_3d.py:nis_3": "as position_stats, in 3D",
            "core/filters/kernels_3d.py:position_stats_3d_c": "as position_stats, in 3D",
            "core/filters/kernels_3d.py:doppler_stats_3d_c": "as position_stats, in 3D",
            "core/filters/kernels_3d.py:doppler_nis_3d": "calls doppler_stats_3d_c",
        },
    ),
    "IMM mode probabilities": StepKind(
        pattern=r"(predicted|updated|mode)_probabilit",
        implementations=frozenset(
            {
                "core/filters/imm_moments.py:predicted_probabilities",
                "core/filters/imm_moments.py:updated_probabilities",
            }
        ),
        not_yet={
            "core/filters/kernels_imm.py:mode_probabilities": (
                "the IMM kernels' own update of μ: bound to the shared one, a split block's "
                "3D IMM results differed from one thread's by rounding"
            ),
        },
    ),
    "semi-definite Cholesky factor": StepKind(
        pattern=r"cholesky",
        implementations=frozenset(
            {
                "core/filters/position_2d.py:semidefinite_cholesky_2d",
                "core/filters/position_3d.py:semidefinite_cholesky_3d",
            }
        ),
        not_this_step={
            "core/filters/joseph.py:cholesky_factor": "the 2D and 3D factor as a dense array",
        },
    ),
}


@dataclass
class Function:
    key: str  # "file:function"
    name: str
    calls: set[str]  # the names it calls or passes on (a step handed to ``step_2d``)


def _uses(node: ast.FunctionDef) -> set[str]:
    """The names a function calls (``f(…)``, ``m.f(…)``, a bound step ``steps["f"](…)``) or
    passes to a call by name (a step handed to the function that applies it, ``step_2d``)."""
    names = set()
    for c in ast.walk(node):
        if not isinstance(c, ast.Call):
            continue
        f = c.func
        if isinstance(f, ast.Name):
            names.add(f.id)
        elif isinstance(f, ast.Attribute):
            names.add(f.attr)
        elif isinstance(f, ast.Subscript) and isinstance(f.slice, ast.Constant):
            names.add(str(f.slice.value))
        names |= {a.id for a in c.args if isinstance(a, ast.Name)}
    return names


@cache
def core_functions() -> tuple[tuple[Function, ...], dict[str, str]]:
    """Every function of core/ with the names it calls, and the module-level aliases
    ``name = wrapper(function)`` and ``name = rebound["function"]`` (a kernel module compiling
    a plain function, ``core.filters.rebind``)."""
    functions: list[Function] = []
    aliases: dict[str, str] = {}
    for path in sorted((ROOT / "core").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef):
                functions.append(Function(f"{rel}:{node.name}", node.name, _uses(node)))
        for node in tree.body:
            if not isinstance(node, ast.Assign):
                continue
            value, target = node.value, None
            if isinstance(value, ast.Call) and value.args and isinstance(value.args[0], ast.Name):
                target = value.args[0].id  # name = wrapper(function)
            elif isinstance(value, ast.Subscript) and isinstance(value.slice, ast.Constant):
                target = str(value.slice.value)  # name = rebound["function"]
            for name in node.targets:
                if target is not None and isinstance(name, ast.Name):
                    aliases[name.id] = target
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
        and f.key not in kind.not_yet
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
        f"{kind_name}: these functions do its work without calling its implementation "
        f"({sorted(kind.implementations)}): {found}"
    )
    keys = {f.key for f in functions}
    stale = [key for key in (*kind.not_this_step, *kind.not_yet) if key not in keys]
    assert not stale, f"{kind_name}: listed but gone (update the table): {stale}"


def test_every_engine_reaches_the_prediction() -> None:
    """The numpy engine, the array-API path and the 2D and 3D kernels all predict through
    the one implementation."""
    reach = built_on(STEP_KINDS["constant-velocity prediction"], *core_functions())
    for name in ("cv_predict", "filter_history_xp", "predict_s", "predict_3d", "predict_models"):
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


def test_a_hand_written_update_is_found() -> None:
    """The same for an update, from source: a UKF re-derived with the elementary functions
    (its locals passed on by name) is reported; one handing the step to the batch applier,
    or calling the array-API path's bound copy, is not."""
    source = """
def ukf_update_fast(x, P, r, b):
    L = cholesky(P)
    return finish(x, P, L, sqrt(r), atan2(b, r), wrap(b))

def ukf_update_batched(state, args, out):
    return step_2d(ukf_update_2d, state, args, out)

def ukf_update_bound(xp, x, P, args):
    return _steps(xp)["ukf_update_2d"](x, P, *args)
"""
    fake = tuple(
        Function(f"core/filters/fast.py:{node.name}", node.name, _uses(node))
        for node in ast.parse(source).body
        if isinstance(node, ast.FunctionDef)
    )
    functions, aliases = core_functions()
    found = copies(STEP_KINDS["polar UKF update"], functions + fake, aliases)
    assert found == ["core/filters/fast.py:ukf_update_fast"]
