"""One name per quantity: the azimuth noise σβ is ``sigma_beta_rad`` / ``sigma_beta_deg``, the
elevation noise σε ``sigma_elevation_rad`` / ``sigma_elevation_deg``, the range noise σr
``sigma_r_m``, the radial-velocity noise σVr ``sigma_vr_mps``, the motion model's acceleration
noise σa ``sigma_a_mps2`` and the start velocity's σv0 ``sigma_v0_mps`` in every signature and
record of ``core`` and ``viz_app``.

Every function's parameters (positional, keyword-only, ``*args``, ``**kwargs``; lambdas too)
and every field of a class whose body declares annotated fields (dataclasses, NamedTuples)
are read from the source with ``ast``; none may be one of the retired names.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("core", "viz_app")
RETIRED = frozenset(
    {
        "sigma_azimuth_rad",
        "sigma_azimuth_deg",
        "sigma_az",
        "sigma_b",
        "sb",
        "sigma_angle_rad",
        "sigma_e",
        "sigma_el",
        "sigma_r",
        "sr",
        "sr_m",
        "sigma_range",
        "sigma_range_m",
        "sigma_vr",
        "svr",
        "svr_mps",
        "sigma_radial_velocity",
        "sigma_radial_velocity_mps",
        "sigma_a",
        "sa",
        "sigma_v0",
        "v0",
    }
)


def sources() -> list[Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def declared_names(tree: ast.AST) -> list[tuple[int, str, str]]:
    """(line, kind, name) of every parameter and every annotated class field in ``tree``."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            a = node.args
            params = a.posonlyargs + a.args + a.kwonlyargs + [p for p in (a.vararg, a.kwarg) if p]
            where = getattr(node, "name", "lambda")
            out += [(p.lineno, f"parameter of {where}", p.arg) for p in params]
        elif isinstance(node, ast.ClassDef):
            out += [
                (s.lineno, f"field of {node.name}", s.target.id)
                for s in node.body
                if isinstance(s, ast.AnnAssign) and isinstance(s.target, ast.Name)
            ]
    return out


def retired_names(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    rel = path.relative_to(ROOT)
    return [
        f"{rel}:{line}: {kind}: {name}"
        for line, kind, name in declared_names(tree)
        if name in RETIRED
    ]


def test_the_walk_sees_parameters_and_fields() -> None:
    code = """
from dataclasses import dataclass
from typing import NamedTuple

def f(a, sb, /, sigma_b=1, *sigma_e, sigma_az, **sigma_el): ...
def h(sr, sr_m, /, sigma_r=1, *svr, sigma_vr, **svr_mps): ...
def k(sigma_a, sa, sigma_v0, v0): ...
g = lambda sigma_angle_rad, sigma_range: 0

@dataclass
class C:
    sigma_azimuth_rad: float
    sigma_range_m: float
    sigma_radial_velocity_mps: float | None = None

class N(NamedTuple):
    sigma_azimuth_deg: float
    sigma_radial_velocity: float
"""
    found = {name for _, _, name in declared_names(ast.parse(code))} & RETIRED
    assert found == RETIRED


def test_no_retired_noise_names() -> None:
    bad = [line for path in sources() for line in retired_names(path)]
    assert not bad, (
        "retired names (sigma_beta_rad/_deg, sigma_elevation_rad/_deg, sigma_r_m,"
        " sigma_vr_mps, sigma_a_mps2 and sigma_v0_mps instead):\n" + "\n".join(bad)
    )
