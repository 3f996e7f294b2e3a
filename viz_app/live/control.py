"""The live tracker's settings as the panel changes them (``viz_app.live.panel``).

The panel's thread hands raw values to :meth:`LiveControl.submit`, which checks them at once
(a bad value is one error line; the tracker keeps the last good settings) and leaves them for
the tracker. The tracker's thread calls :meth:`LiveControl.apply` before every run of the
held batches, so a change applies from the next plot tracked on:

* σa (``cv``: one σa; ``imm``: a σa per model, as many as before), the gate probability, the
  M-of-N confirmation and the deletion rule are taken by the running tracker
  (``GNNTracker.retune``): every track is kept;
* another motion model (``cv`` ↔ ``imm``, or another number of IMM models) changes what a
  track holds: a new tracker starts, the old tracks leave the viewer, and the new ones are
  named ``g<k>-<id>`` (``k`` the tracker's generation: ids start at 1 again);
* the methods shown only change what the viewer gets (every method is still tracked).
"""

from __future__ import annotations

import dataclasses
import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from radarviz.core.params import ParameterError, check, check_choice
from radarviz.core.tracking.association import AssociationOptions, GNNTracker
from radarviz.core.tracking.stream import MOTION_MODELS, StreamOptions


@dataclass(frozen=True)
class LiveSettings:
    """What the panel sets: the motion model and its σa (``sigma_a_mps2`` for ``cv``,
    ``imm_sigma_a_mps2`` for ``imm``), the gate probability, the M-of-N confirmation, the
    misses that delete a confirmed track, and the methods shown (of the tracked ones)."""

    model: str
    sigma_a_mps2: float
    imm_sigma_a_mps2: tuple[float, ...]
    gate_probability: float
    confirm_m: int
    confirm_n: int
    delete_misses: int
    shown: tuple[str, ...]

    @classmethod
    def of(
        cls, options: StreamOptions, association: AssociationOptions, shown: tuple[str, ...]
    ) -> LiveSettings:
        """The settings a tracker runs with."""
        return cls(
            options.model,
            options.sigma_a_mps2,
            tuple(options.imm_sigma_a_mps2),
            association.gate_probability,
            association.confirm_m,
            association.confirm_n,
            association.delete_misses,
            tuple(shown),
        )

    def options(
        self, options: StreamOptions, association: AssociationOptions
    ) -> tuple[StreamOptions, AssociationOptions]:
        """``options`` and ``association`` with these settings; each value checked there
        (ParameterError naming it)."""
        new = replace(
            options,
            model=self.model,
            sigma_a_mps2=self.sigma_a_mps2,
            imm_sigma_a_mps2=self.imm_sigma_a_mps2,
        )
        rules = replace(
            association,
            gate_probability=self.gate_probability,
            confirm_m=self.confirm_m,
            confirm_n=self.confirm_n,
            delete_misses=self.delete_misses,
        )
        return new, rules


def _integer(name: str, value: Any) -> int:
    """A whole number from a panel input (a float such as 3.0 is accepted)."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ParameterError(f"{name} must be a whole number (got {value!r})", name)
    return value


def _sigmas(value: Any) -> tuple[float, ...]:
    """The IMM's σa per model from a list or from text such as ``"0.5, 10, 30"``."""
    if isinstance(value, str):
        parts = [p for p in value.replace(",", " ").split() if p]
        try:
            value = [float(p) for p in parts]
        except ValueError:
            raise ParameterError(
                f"imm_sigma_a_mps2 must be numbers, one per model (got {value!r})",
                "imm_sigma_a_mps2",
            ) from None
    out = tuple(float(v) for v in value)
    if not out:
        raise ParameterError("imm_sigma_a_mps2: give one σa per model", "imm_sigma_a_mps2")
    for v in out:
        check("imm_sigma_a_mps2", v)
    return out


def settings_from_raw(raw: dict[str, Any], tracked: tuple[str, ...]) -> LiveSettings:
    """Checked settings from panel values (ParameterError naming the first bad one)."""
    model = check_choice("model", raw["model"], MOTION_MODELS)
    sigma_a_mps2 = check("sigma_a_mps2", float(raw["sigma_a_mps2"]))
    shown = tuple(raw["shown"])
    if not shown:
        raise ParameterError(f"methods: show at least one of {', '.join(tracked)}", "methods")
    for m in shown:
        check_choice("method", m, tracked)
    gate = raw["gate_probability"]
    if not isinstance(gate, int | float) or not math.isfinite(gate):
        raise ParameterError(
            f"gate_probability must be a number (got {gate!r})", "gate_probability"
        )
    return LiveSettings(
        model,
        sigma_a_mps2,
        _sigmas(raw["imm_sigma_a_mps2"]),
        float(gate),
        _integer("confirm_m", raw["confirm_m"]),
        _integer("confirm_n", raw["confirm_n"]),
        _integer("delete_misses", raw["delete_misses"]),
        shown,
    )


class LiveControl:
    """The tracker of a live session and the settings waiting for it (module docstring).

    ``tracker`` is the running tracker (a new one after a change of motion model; its
    ``generation`` counts them). ``make`` builds a tracker of given options. ``listeners``
    are called (with this control) after every submission and every change applied.
    """

    def __init__(
        self,
        tracker: GNNTracker,
        options: StreamOptions,
        association: AssociationOptions,
        make: Callable[[StreamOptions, AssociationOptions], GNNTracker],
    ):
        self.tracker = tracker
        self.make = make
        self._options, self._association = options, association
        self.settings = LiveSettings.of(options, association, tracker.methods)
        self.generation = 0
        #: Changes of settings applied so far.
        self.applied = 0
        self.error = ""
        self.status = "running with the settings it started with"
        self.listeners: list[Callable[[LiveControl], None]] = []
        self._lock = threading.Lock()
        self._pending: tuple[LiveSettings, StreamOptions, AssociationOptions] | None = None

    @property
    def options(self) -> tuple[StreamOptions, AssociationOptions]:
        """The filters' and the association's options in force."""
        return self._options, self._association

    def submit(self, raw: dict[str, Any]) -> str:
        """Check panel values and leave them for the tracker; returns the error line ("" if
        none). A bad value leaves the settings waiting or in force unchanged."""
        try:
            settings = settings_from_raw(raw, self.tracker.methods)
            options, association = settings.options(self._options, self._association)
        except (ParameterError, TypeError, ValueError, KeyError) as exc:
            self.error = f"{exc} (the tracker keeps its last good settings)"
        else:
            self.error = ""
            with self._lock:
                self._pending = (settings, options, association)
        self._tell()
        return self.error

    def apply(self, on_restart: Callable[[list[str]], None] | None = None) -> bool:
        """In the tracker's thread, before a run: take the waiting settings (if any).
        ``on_restart`` gets the old tracker's live track ids (as the viewer names them)
        when a new tracker replaces it. Returns whether settings were taken."""
        with self._lock:
            pending, self._pending = self._pending, None
        if pending is None:
            return False
        settings, options, association = pending
        if (options, association) == (self._options, self._association):
            self.settings = settings  # only the methods shown
            self.status = "methods shown changed"
        else:
            try:
                self.tracker.retune(options, association)
                self.status = "applied from the next plot on; every track kept"
            except ParameterError as exc:
                if exc.parameter not in ("model", "imm_sigma_a_mps2"):
                    self.error = f"{exc} (the tracker keeps its last good settings)"
                    self._tell()
                    return False
                old = [self.track_id(t) for t in self.tracker.live()]
                self.tracker = self.make(options, association)
                self.generation += 1
                if on_restart is not None:
                    on_restart(old)
                self.status = (
                    f"new motion model: the tracks started again (tracker {self.generation}, "
                    f"{len(old)} tracks dropped)"
                )
            self.settings = settings
            self._options, self._association = options, association
        self.applied += 1
        self._tell()
        return True

    def track_id(self, track: str) -> str:
        """A track's id as the viewer names it: ``g<k>-<id>`` after ``k`` restarts."""
        return track if self.generation == 0 else f"g{self.generation}-{track}"

    def document(self) -> dict[str, Any]:
        """The settings in force, for the summary."""
        doc = dataclasses.asdict(self.settings)
        doc["imm_sigma_a_mps2"] = list(doc["imm_sigma_a_mps2"])
        doc["shown"] = list(doc["shown"])
        doc["generation"] = self.generation
        return doc

    def _tell(self) -> None:
        for listener in self.listeners:
            listener(self)
