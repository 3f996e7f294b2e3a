"""``radarviz live --panel``: the Viser controls that change the live tracker while it runs.

The panel is ``tune``'s (``viz_app.tune``): the same guarded server (``tune.guard``: bound
to ``--host``, 127.0.0.1 by default, answering only its printed address with its token, and
refusing other Host names and Origins), the same two-frame page with the viewer beside the
controls (``tune.page``). Its controls: the motion model and σa (one for ``cv``, one per model
for ``imm``), the gate probability P_G, the M-of-N confirmation, the misses that delete a
confirmed track, and the methods shown. Each change goes to ``LiveControl.submit`` (after a
pause of ``SETTLE_S`` for typed numbers, at once for the others): a bad value is one error
line and the tracker keeps its last good settings; a good one applies from the next plot
tracked on (``viz_app.live.control`` says which changes keep the tracks).
"""

from __future__ import annotations

import threading
from typing import Any

from radarviz.core.filters.models import MOTION_MODELS
from radarviz.core.params import PARAMETERS
from radarviz.viz_app.live.control import LiveControl
from radarviz.viz_app.tune.panel import SETTLE_S, lay_out_panel, parameter_label

#: The number inputs, in panel order: setting → step.
NUMBERS: dict[str, float] = {
    "sigma_a_mps2": 0.5,
    "gate_probability": 0.001,
    "confirm_m": 1,
    "confirm_n": 1,
    "delete_misses": 1,
}


class LivePanel:
    """The controls of one live session (module docstring), on Viser ``server``'s GUI."""

    def __init__(self, server: Any, control: LiveControl):
        self.server, self.control = server, control
        s = control.settings
        gui = server.gui
        lay_out_panel(server)
        gui.add_markdown(
            "## radarviz live\nA change applies from the next plot tracked on. σa, P_G, the "
            "confirmation and the deletion keep every track; **another motion model starts "
            "the tracks again** (the old ones leave the viewer). Typed numbers apply after a "
            f"{SETTLE_S:g} s pause."
        )
        self.model = gui.add_dropdown(
            "motion model", tuple(MOTION_MODELS), initial_value=s.model,
            hint="cv: one σa; imm: a σa per model (another number of models starts again)",
        )  # fmt: skip
        initial = {n: getattr(s, n) for n in NUMBERS}
        self.numbers = {
            n: gui.add_number(
                parameter_label(n),
                initial[n],
                step=step,
                hint=PARAMETERS[n].help(),
                min=PARAMETERS[n].low,
                max=PARAMETERS[n].high,
            )
            for n, step in NUMBERS.items()
        }
        self.imm_sigmas = gui.add_text(
            f"{parameter_label('imm_sigma_a_mps2')}, per model",
            ", ".join(f"{v:g}" for v in s.imm_sigma_a_mps2),
            hint=PARAMETERS["imm_sigma_a_mps2"].help(),
        )
        gui.add_markdown("**methods shown**")
        self.methods = {m: gui.add_checkbox(m, m in s.shown) for m in control.tracker.methods}
        self.error_md = gui.add_markdown("")
        self.status_md = gui.add_markdown("")
        self._timer: threading.Timer | None = None
        self._lock = threading.Lock()
        for h in (*self.numbers.values(), self.imm_sigmas):
            h.on_update(self._typed)
        for h in (self.model, *self.methods.values()):
            h.on_update(self._changed)
        self._show_model()
        control.listeners.append(self.refresh)
        self.refresh(control)

    def raw(self) -> dict[str, Any]:
        """The controls' values, for ``LiveControl.submit``."""
        return {
            "model": self.model.value,
            **{n: h.value for n, h in self.numbers.items()},
            "imm_sigma_a_mps2": self.imm_sigmas.value,
            "shown": tuple(m for m, h in self.methods.items() if h.value),
        }

    def submit(self) -> str:
        """Hand the controls' values to the tracker now; the error line ("" if none)."""
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
        return self.control.submit(self.raw())

    def _show_model(self) -> None:
        cv = self.model.value == "cv"
        self.numbers["sigma_a_mps2"].visible = cv
        self.imm_sigmas.visible = not cv

    def _typed(self, _event: Any = None) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
            self._timer = threading.Timer(SETTLE_S, self.submit)
            self._timer.daemon = True
            self._timer.start()

    def _changed(self, _event: Any = None) -> None:
        self._show_model()
        self.submit()

    def refresh(self, control: LiveControl) -> None:
        """The error and status lines from the control."""
        self.error_md.content = f"**error:** {control.error}" if control.error else ""
        s = control.settings
        sigma = (
            f"σa {s.sigma_a_mps2:g} m/s²"
            if s.model == "cv"
            else "σa " + ", ".join(f"{v:g}" for v in s.imm_sigma_a_mps2) + " m/s²"
        )
        self.status_md.content = (
            f"{control.status}.  \nIn force: {s.model}, {sigma}, P_G {s.gate_probability:g}, "
            f"{s.confirm_m} of {s.confirm_n}, delete after {s.delete_misses} misses; "
            f"showing {', '.join(s.shown)}"
        )

    def close(self) -> None:
        with self._lock:
            if self._timer is not None:
                self._timer.cancel()
