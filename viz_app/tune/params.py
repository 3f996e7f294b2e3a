"""What the tuning panel controls: one set of values shared by the three scenes.

Every numeric field is a ``core.params.PARAMETERS`` entry, checked against it (with the panel's
tighter ``TUNE_LIMITS``), so a bad value reads as on the command line: ``sigma_r_m must be a
finite number in (0, 1e+06] (got -5)``. Where each value enters:

=========  =====================================================================================
σr         Prosov's radar; the finite-memory windows and the Doppler start; every radar of the
           velocity scene
σβ         Prosov's azimuth noise; the Doppler start's azimuth noise; every velocity radar's
           azimuth and elevation noise
T          every scan period (Prosov, finite memory, Doppler start, velocity radars)
C0         C0 = σr² / (T² σVr²): σVr = σr / (T √C0) of the finite memory, the Doppler start and
           the velocity radars (Prosov uses positions only)
σVr        the same Doppler accuracy given directly (the panel takes σVr or C0, the user's
           choice, and derives the other with σr and T)
runs       Monte Carlo runs of the scene (Prosov filters, Gorshkov trials and Doppler start)
seed       the root of every random stream
=========  =====================================================================================

:data:`SCENE_PARAMETERS` lists the values each scene reads; the panel hides the others (a
change of C0 in the Prosov scene would re-run an identical scene).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from radarviz.core.experiments.prosov import ALL_METHODS, BLOCK_RUNS
from radarviz.core.finite_memory.fit import PRESETS, c0_ratio
from radarviz.core.params import ParameterError, check, check_choice, default

#: The scenes the panel can run, in selector order: name → title.
SCENES: dict[str, str] = {
    "prosov": "Prosov: converted measurements",
    "gorshkov": "Gorshkov: finite memory and the Doppler start",
    "velocity": "Velocity: several radars' radial velocities",
}
#: The values each scene reads (``sigma_vr_mps`` stands for the Doppler accuracy, σVr or C0):
#: a control outside its scene's set cannot change that scene's result. The velocity scene is
#: one draw of its radars' measurements per scan (no Monte Carlo runs), and only Prosov runs
#: several tracking methods.
SCENE_PARAMETERS: dict[str, frozenset[str]] = {
    "prosov": frozenset({"sigma_r_m", "sigma_beta_deg", "period_s", "runs", "seed", "methods"}),
    "gorshkov": frozenset(
        {"sigma_r_m", "sigma_beta_deg", "period_s", "sigma_vr_mps", "runs", "seed"}
    ),
    "velocity": frozenset({"sigma_r_m", "sigma_beta_deg", "period_s", "sigma_vr_mps", "seed"}),
}
#: Largest run count the panel accepts (one block of the Monte Carlo engine).
MAX_TUNE_RUNS = min(5000, BLOCK_RUNS)
#: The panel's tighter upper ends of table parameters (fast re-runs; seeds a number input holds).
TUNE_LIMITS: dict[str, float] = {"runs": MAX_TUNE_RUNS, "seed": 2**32 - 1, "steps": 1000}


@dataclass(frozen=True)
class TuneParams:
    """The panel's values. Validated on construction (ParameterError, one line).

    The panel starts at σβ = 2° (where the conversions differ visibly) and 200 runs; the rest
    are the table's defaults. ``c0`` is C0 = σr² / (T² σVr²); σVr follows (:attr:`sigma_vr_mps`).
    """

    scene: str = "prosov"
    sigma_r_m: float = default("sigma_r_m")
    sigma_beta_deg: float = 2.0
    period_s: float = default("period_s")
    c0: float = default("c0")
    methods: tuple[str, ...] = ALL_METHODS
    runs: int = 200
    seed: int = default("seed")
    steps: int = default("steps")

    def __post_init__(self) -> None:
        check_choice("scene", self.scene, SCENES)
        for name in ("sigma_r_m", "sigma_beta_deg", "period_s", "c0", "runs", "seed", "steps"):
            check(name, getattr(self, name), high=TUNE_LIMITS.get(name))
        if not self.methods:
            raise ParameterError(f"methods: select at least one of {', '.join(ALL_METHODS)}")
        for m in self.methods:
            check_choice("method", m, ALL_METHODS)

    @property
    def sigma_vr_mps(self) -> float:
        """σVr that gives C0 with this σr and T: σVr = σr / (T √C0)."""
        return sigma_vr_from_c0(self.sigma_r_m, self.period_s, self.c0)

    @classmethod
    def from_raw(cls, raw: dict[str, Any]) -> TuneParams:
        """From panel values (floats from number inputs are accepted for integer fields).

        A ``sigma_vr_mps`` (σVr typed instead of C0) is checked and turned into
        C0 = σr² / (T² σVr²) with the σr and T given (each checked first).
        """
        kw = dict(raw)
        if "sigma_vr_mps" in kw:
            sigma_vr_mps = check("sigma_vr_mps", kw.pop("sigma_vr_mps"))
            sigma_r_m = check("sigma_r_m", kw.get("sigma_r_m", default("sigma_r_m")))
            period_s = check("period_s", kw.get("period_s", default("period_s")))
            kw["c0"] = c0_ratio(sigma_r_m=sigma_r_m, sigma_vr_mps=sigma_vr_mps, period_s=period_s)
        for name in ("runs", "seed", "steps"):
            v = kw.get(name)
            if isinstance(v, float) and v.is_integer():
                kw[name] = int(v)
        if "methods" in kw:
            kw["methods"] = tuple(kw["methods"])
        return cls(**kw)


def sigma_vr_from_c0(sigma_r_m: float, period_s: float, c0: float) -> float:
    """σVr = σr / (T √C0), m/s; each input checked first, so an invalid σr, T or C0 never
    yields a σVr (ParameterError naming the input)."""
    check("sigma_r_m", sigma_r_m)
    check("period_s", period_s)
    check("c0", c0)
    return sigma_r_m / (period_s * math.sqrt(c0))


def preset_values(name: str) -> dict[str, float]:
    """σr, T and C0 (from σVr) of a Gorshkov radar preset RLS1 … RLS6."""
    p = PRESETS[check_choice("preset", name, PRESETS)]
    return {
        "sigma_r_m": p.sigma_r_m,
        "period_s": p.period_s,
        "c0": c0_ratio(sigma_r_m=p.sigma_r_m, sigma_vr_mps=p.sigma_vr_mps, period_s=p.period_s),
    }
