"""``radarviz tune``: the Viser panel's controls (``serve`` starts it with its servers).

Every control acts where its parameter enters the chosen scene (``tune.params``), and only
the controls the chosen scene reads are shown (``SCENE_PARAMETERS``). The Doppler accuracy is
one control, entered as σVr or as C0 (the user's choice; the other is derived and shown).
Typed numbers apply after a pause of ``SETTLE_S`` (a half-typed "0.3" is never run as 0); the
σβ slider's steps come the same way as the keystrokes in its number box, so they wait too. A
value the page reports finished (a slider let go, Enter in a number box:
:meth:`TunePanel.finished`) runs at once. The scene, the preset and the method boxes apply at
once. A bad value is one error line naming the parameter and its range, and the last good run
stays on screen.
"""

from __future__ import annotations

import contextlib
import math
from typing import Any

from radarviz.core.experiments.prosov import ALL_METHODS
from radarviz.core.finite_memory.fit import PRESETS, c0_ratio
from radarviz.core.params import PARAMETERS, ParameterError, check
from radarviz.viz_app.tune.page import CONTROLS_MIN_PX
from radarviz.viz_app.tune.params import (
    SCENE_PARAMETERS,
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
    "sigma_vr_mps": ("number", 0.1, None),
    "runs": ("number", 1, "Monte Carlo runs"),
    "seed": ("number", 1, "seed"),
}
#: Pause (s) after the last keystroke or slider step before a value is run.
SETTLE_S = 0.5
#: The choice of how the Doppler accuracy is entered: label → the control it shows.
DOPPLER_INPUTS: dict[str, str] = {"σVr (m/s)": "sigma_vr_mps", "C0": "c0"}


def _same(raw: Any, value: float) -> bool:
    """Whether the panel value ``raw`` is the number ``value`` (False for no number)."""
    try:
        return math.isclose(float(raw), value, rel_tol=1e-9, abs_tol=1e-12)
    except (TypeError, ValueError):
        return False


def parameter_label(name: str) -> str:
    """The panel label of table parameter ``name``: its symbol and unit (``σβ (deg)``)."""
    p = PARAMETERS[name]
    return f"{p.symbol} ({p.unit})" if p.unit else p.symbol


def lay_out_panel(server: Any) -> None:
    """Dock a Viser panel's controls at the left of its page, at the width the page gives
    them (``page.CONTROLS_MIN_PX``), and hide its 3D scene's axes (the scene lives in the
    viewer, not here); a Viser without these settings keeps its own layout."""
    gui = server.gui
    with contextlib.suppress(Exception):
        server.scene.world_axes.visible = False
    with contextlib.suppress(Exception):
        gui.configure_theme(control_width="large", show_logo=False, show_share_button=False)
        gui.main_panel.dock_left()
        gui.main_panel.set_width(CONTROLS_MIN_PX)


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
        "label": label or parameter_label(name),
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
        lay_out_panel(server)
        gui.add_markdown(
            "## radarviz tune\nEach change re-runs the chosen scene; the Rerun viewer beside "
            f"these controls switches to the new run. Typed numbers apply after a {SETTLE_S:g} s "
            "pause or on Enter, the slider when let go; only the values the scene reads are "
            "shown."
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
            hint="RLS1 … RLS6 fill σr, T and the Doppler accuracy σVr (C0)",
        )
        self.doppler_input = gui.add_dropdown(
            "Doppler accuracy as",
            tuple(DOPPLER_INPUTS),
            initial_value="C0",
            hint="enter σVr and derive C0 = σr²/(T²σVr²), or enter C0 and derive σVr = σr/(T√C0)",
        )
        initial_values = {n: getattr(p, n) for n in TUNE_CONTROLS if n != "sigma_vr_mps"}
        initial_values["sigma_vr_mps"] = round(p.sigma_vr_mps, 6)  # p carries C0
        self.controls = {n: add_control(gui, n, initial_values[n]) for n in TUNE_CONTROLS}
        self.derived = gui.add_markdown("")
        self.methods_title = gui.add_markdown("**methods shown**")
        self.methods = {m: gui.add_checkbox(m, m in p.methods) for m in ALL_METHODS}
        self.save_button = gui.add_button("save recording")
        self.error_md = gui.add_markdown("")
        self.status_md = gui.add_markdown(session.status_markdown())
        self._steps = p.steps
        self._last_typed: str | None = None  # the control the newest typed value is from
        for h in self.controls.values():
            h.on_update(self._typed)
        for h in (self.scene, self.doppler_input, *self.methods.values()):
            h.on_update(self._changed)
        self.preset.on_update(self._preset_changed)
        self.save_button.on_click(self._save)
        session.listeners.append(self.refresh)
        self._show_scene_controls()

    # --- what is shown ---------------------------------------------------------------------

    @property
    def doppler_name(self) -> str:
        """The Doppler control the user types into: ``sigma_vr_mps`` or ``c0``."""
        return DOPPLER_INPUTS[self.doppler_input.value]

    def _show_scene_controls(self) -> None:
        """Show only the controls the chosen scene reads (``SCENE_PARAMETERS``)."""
        reads = SCENE_PARAMETERS[self.scene.value]
        doppler = "sigma_vr_mps" in reads
        for name, handle in self.controls.items():
            if name in ("c0", "sigma_vr_mps"):
                handle.visible = doppler and name == self.doppler_name
            else:
                handle.visible = name in reads
        self.doppler_input.visible = self.derived.visible = doppler
        methods = "methods" in reads
        self.methods_title.visible = methods
        for h in self.methods.values():
            h.visible = methods
        self.derived.content = self._derived_text(self.raw_values())

    @staticmethod
    def _sigma_vr_text(sigma_r_m: Any, period_s: Any, c0: Any) -> str:
        """σVr = σr / (T √C0), or why there is none (an invalid σr, T or C0)."""
        try:
            v = sigma_vr_from_c0(float(sigma_r_m), float(period_s), float(c0))
        except (ParameterError, TypeError, ValueError) as exc:
            return f"σVr = σr/(T√C0): — ({exc})"
        return f"σVr = σr/(T√C0) = **{v:.4g} m/s**"

    @staticmethod
    def _c0_text(sigma_r_m: Any, period_s: Any, sigma_vr_mps: Any) -> str:
        """C0 = σr² / (T² σVr²), or why there is none (an invalid σr, T or σVr)."""
        try:
            c0 = c0_ratio(
                sigma_r_m=check("sigma_r_m", float(sigma_r_m)),
                sigma_vr_mps=check("sigma_vr_mps", float(sigma_vr_mps)),
                period_s=check("period_s", float(period_s)),
            )
        except (ParameterError, TypeError, ValueError) as exc:
            return f"C0 = σr²/(T²σVr²): — ({exc})"
        return f"C0 = σr²/(T²σVr²) = **{c0:.4g}**"

    def _derived_text(self, values: dict[str, Any]) -> str:
        sigma_r_m, t = values["sigma_r_m"], values["period_s"]
        if self.doppler_name == "c0":
            return self._sigma_vr_text(sigma_r_m, t, values["c0"])
        return self._c0_text(sigma_r_m, t, values["sigma_vr_mps"])

    # --- values -----------------------------------------------------------------------------

    def raw_values(self) -> dict[str, Any]:
        return {name: h.value for name, h in self.controls.items()}

    def raw(self) -> dict[str, Any]:
        """The panel's values for ``TuneParams.from_raw``: the Doppler accuracy as typed (σVr
        or C0), the other one left out."""
        values = self.raw_values()
        other = "c0" if self.doppler_name == "sigma_vr_mps" else "sigma_vr_mps"
        values.pop(other)
        return {
            "scene": self.scene.value,
            **values,
            "steps": self._steps,
            "methods": tuple(m for m, h in self.methods.items() if h.value),
        }

    def _submit(self, settle_s: float) -> None:
        self.derived.content = self._derived_text(self.raw_values())
        self.worker.submit(self.raw(), settle_s=settle_s)

    def _typed(self, event: Any = None) -> None:
        """A number or the slider: run once the typing has paused."""
        target = getattr(event, "target", None)
        self._last_typed = next((n for n, h in self.controls.items() if h is target), None)
        self._submit(SETTLE_S)

    def finished(self, value: float) -> str | None:
        """The page saw the user finish ``value`` (a slider let go, Enter in a number box): run
        it without the settling pause. Returns the control the report was taken for (None: no
        value typed yet).

        Viser sends a slider's steps and a number box's keystrokes alike, so the worker cannot
        tell a finished value from a half-typed one; the page can (``tune.page``). The report
        is about the control last typed into or moved: the pending run is hurried if that
        control holds ``value`` in it. If the value has not reached the panel yet (it comes by
        Viser's WebSocket, the report by a request of its own), the worker waits one pause
        for it.
        """
        name = self._last_typed
        if name is None:
            return None

        def match(raw: Any) -> bool:
            return isinstance(raw, dict) and _same(raw.get(name), value)

        arrived = _same(self.controls[name].value, value)
        self.worker.hurry(match, expect_s=0.0 if arrived else SETTLE_S)
        return name

    def _changed(self, _event: Any = None) -> None:
        """The scene, the Doppler input or a method box: show its controls and run at once."""
        self._show_scene_controls()
        self._submit(0.0)

    def _preset_changed(self, _event: Any = None) -> None:
        if self.preset.value == "custom":
            return
        v = preset_values(self.preset.value)
        self.controls["sigma_r_m"].value = v["sigma_r_m"]
        self.controls["period_s"].value = v["period_s"]
        self.controls["c0"].value = round(v["c0"], 4)
        self.controls["sigma_vr_mps"].value = round(
            sigma_vr_from_c0(v["sigma_r_m"], v["period_s"], v["c0"]), 6
        )
        self._submit(0.0)

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
