"""``radarviz tune``: the Viser panel's controls (``serve`` starts it with its servers).

Every control acts where its parameter enters the chosen scene (``tune.params``); a bad value
is one error line naming the parameter and its range, and the last good run stays on screen.
"""

from __future__ import annotations

import contextlib
from typing import Any

from radarviz.core.experiments.prosov import ALL_METHODS
from radarviz.core.finite_memory.fit import PRESETS
from radarviz.core.params import PARAMETERS, ParameterError
from radarviz.viz_app.tune.params import (
    SCENES,
    TUNE_LIMITS,
    TuneParams,
    preset_values,
    sigma_vr_from_c0,
)
from radarviz.viz_app.tune.session import TuneSession
from radarviz.viz_app.tune.worker import Coalescer

#: Controls built from the parameter table, in panel order: name → (kind of input, step,
#: label; None: the table's symbol and unit, e.g. "σβ (deg)").
TUNE_CONTROLS: dict[str, tuple[str, float, str | None]] = {
    "sigma_r_m": ("number", 1.0, None),
    "sigma_beta_deg": ("slider", 0.1, None),
    "period_s": ("number", 0.5, None),
    "c0": ("number", 0.01, None),
    "runs": ("number", 1, "Monte Carlo runs"),
    "seed": ("number", 1, "seed"),
}


def control_spec(name: str) -> dict[str, Any]:
    """Label, bounds, step and hint of the panel input for table parameter ``name``.

    The label is the symbol and unit (``σβ (deg)``), the hint the table's help line. Number
    inputs get the table's ends as min and max (an open end is not enforced by the input: the
    check then reports it); the slider runs from the table's low end to its high end.
    """
    p = PARAMETERS[name]
    kind, step, label = TUNE_CONTROLS[name]
    high = TUNE_LIMITS.get(name, p.high)
    return {
        "kind": kind,
        "label": label or (f"{p.symbol} ({p.unit})" if p.unit else p.symbol),
        "min": p.low,
        "max": high,
        "step": step,
        "hint": p.help(),
    }


def add_control(gui: Any, name: str, initial: float) -> Any:
    """A Viser input for table parameter ``name`` (:func:`control_spec`) starting at ``initial``."""
    spec = control_spec(name)
    if spec["kind"] == "slider":
        return gui.add_slider(
            spec["label"],
            min=spec["min"],
            max=spec["max"],
            step=spec["step"],
            initial_value=initial,
            hint=spec["hint"],
        )
    return gui.add_number(
        spec["label"],
        initial,
        min=spec["min"],
        max=spec["max"],
        step=spec["step"],
        hint=spec["hint"],
    )


class TunePanel:
    """The Viser controls: the scene selector, the radar values, the status and error lines.

    Every browser tab connected to the server shares this one set of controls (Viser's
    server-level GUI): a change in one tab shows in all, and closing one leaves the others.
    """

    def __init__(
        self,
        server: Any,
        session: TuneSession,
        worker: Coalescer,
        initial: TuneParams | None = None,
    ) -> None:
        p = initial or TuneParams()
        self.server, self.session, self.worker = server, session, worker
        gui = server.gui
        with contextlib.suppress(Exception):
            gui.configure_theme(control_layout="fixed", control_width="large", show_logo=False)
        gui.add_markdown(
            "## radarviz tune\nEach change re-runs the chosen scene; the Rerun viewer (its own "
            "tab) switches to the new run. Number fields ignore text that is not a number."
        )
        self.scene = gui.add_dropdown(
            "scene",
            tuple(SCENES),
            initial_value=p.scene,
            hint="; ".join(f"{k}: {v}" for k, v in SCENES.items()),
        )
        self.preset = gui.add_dropdown(
            "preset",
            ("custom", *PRESETS),
            initial_value="custom",
            hint="RLS1 … RLS6 fill σr, T and C0 (from σVr)",
        )
        self.controls = {name: add_control(gui, name, getattr(p, name)) for name in TUNE_CONTROLS}
        self.sigma_r, self.sigma_beta, self.period, self.c0, self.runs, self.seed = (
            self.controls.values()
        )
        self.sigma_vr = gui.add_markdown(self._sigma_vr_text(p.sigma_r_m, p.period_s, p.c0))
        gui.add_markdown("**methods shown** (Prosov)")
        self.methods = {m: gui.add_checkbox(m, m in p.methods) for m in ALL_METHODS}
        self.save_button = gui.add_button("save recording")
        self.error_md = gui.add_markdown("")
        self.status_md = gui.add_markdown(session.status_markdown())
        self._steps = p.steps
        for h in (self.scene, *self.controls.values(), *self.methods.values()):
            h.on_update(self._changed)
        self.preset.on_update(self._preset_changed)
        self.save_button.on_click(self._save)
        session.listeners.append(self.refresh)
        with contextlib.suppress(Exception):  # the scene lives in the viewer, not here
            server.scene.world_axes.visible = False

    @staticmethod
    def _sigma_vr_text(sigma_r_m: Any, period_s: Any, c0: Any) -> str:
        """σVr = σr / (T √C0), or why there is none (an invalid σr, T or C0)."""
        try:
            v = sigma_vr_from_c0(float(sigma_r_m), float(period_s), float(c0))
        except (ParameterError, TypeError, ValueError) as exc:
            return f"σVr = σr/(T√C0): — ({exc})"
        return f"σVr = σr/(T√C0) = **{v:.4g} m/s**"

    def raw(self) -> dict[str, Any]:
        return {
            "scene": self.scene.value,
            **{name: h.value for name, h in self.controls.items()},
            "steps": self._steps,
            "methods": tuple(m for m, h in self.methods.items() if h.value),
        }

    def _changed(self, _event: Any = None) -> None:
        raw = self.raw()
        self.sigma_vr.content = self._sigma_vr_text(raw["sigma_r_m"], raw["period_s"], raw["c0"])
        self.worker.submit(raw)

    def _preset_changed(self, _event: Any = None) -> None:
        if self.preset.value == "custom":
            return
        v = preset_values(self.preset.value)
        self.sigma_r.value = v["sigma_r_m"]
        self.period.value = v["period_s"]
        self.c0.value = round(v["c0"], 4)
        self._changed()

    def _save(self, _event: Any = None) -> None:
        try:
            path = self.session.save()
            self.error_md.content = f"saved `{path}`"
            print(f"saved {path}", flush=True)
        except Exception as exc:
            self.error_md.content = f"**save failed:** {exc}"

    def refresh(self, session: TuneSession) -> None:
        err = session.last_error
        self.error_md.content = f"**error:** {err} (showing the last good run)" if err else ""
        self.status_md.content = session.status_markdown()
