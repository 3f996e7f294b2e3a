"""A tuning session: panel values → a new recording on the gRPC server, per run.

Each run is logged as a NEW recording id (application id ``radarviz``) so the web viewer
switches to it; the last good run and the last error are kept, and listeners (the panel) are
told after every run. Bad values (``ParameterError``) and results that are not finite
(``ResultError``: a NaN, a negative NEES) become the error line; the last good run stays on
screen.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb

from radarviz.core.finite import ResultError
from radarviz.core.params import ParameterError
from radarviz.viz_app.rerun import gorshkov_scene, prosov_scene, velocity_scene
from radarviz.viz_app.rerun.recording import APPLICATION_ID, log_text, recording_file
from radarviz.viz_app.rerun.scenes import blueprint, text_log_view
from radarviz.viz_app.tune.params import SCENES, TuneParams
from radarviz.viz_app.tune.scenes import (
    PANEL_RADAR,
    TuneResult,
    log_result,
    simulate,
    status_lines,
)

RECORDINGS_DIR = Path("recordings")
_BLUEPRINTS: dict[str, Any] = {}
_BLUEPRINT_LOCK = threading.Lock()


def scene_blueprint(scene: str) -> rrb.Blueprint:
    """The tabs a scene opens on in the panel's viewer (bounds fixed: the scene's transforms
    carry the scale, so one blueprint per scene serves every parameter set)."""
    log_tab = rrb.Vertical(text_log_view(), name="log")
    if scene == "prosov":
        return blueprint(prosov_scene.views(prosov_scene.METHODS_SHOWN), log_tab)
    if scene == "gorshkov":
        return blueprint(
            gorshkov_scene.views((PANEL_RADAR,)),
            gorshkov_scene.start_views(),
            log_tab,
        )
    return blueprint(velocity_scene.views(velocity_scene.panel_frame()).tab, log_tab)


def send_blueprint(rec: rr.RecordingStream, scene: str) -> None:
    """Send the scene's blueprint, built once per scene.

    ``rec.send_blueprint`` builds a new in-memory blueprint stream on every call, and
    rerun-sdk 0.41 never frees it (two native threads each); reusing the built storage keeps
    the thread count flat over any number of runs.
    """
    from rerun.blueprint.api import create_in_memory_blueprint

    with _BLUEPRINT_LOCK:
        storage = _BLUEPRINTS.get(scene)
        if storage is None:
            built = create_in_memory_blueprint(
                application_id=APPLICATION_ID, blueprint=scene_blueprint(scene)
            )
            storage = _BLUEPRINTS[scene] = built.storage
    rr.bindings.send_blueprint(storage, True, True, recording=rec.to_native())


def log_tuning_scene(rec: rr.RecordingStream, params: TuneParams) -> TuneResult:
    """Simulate ``params`` and log its scene (the viewer's scene module) and blueprint."""
    result = simulate(params)
    log_result(rec, result)
    send_blueprint(rec, params.scene)
    p = params
    log_text(
        rec,
        f"tune {p.scene}: {p.runs} runs × {p.steps} scans, σr = {p.sigma_r_m:g} m, "
        f"σβ = {p.sigma_beta_deg:g}°, T = {p.period_s:g} s, C0 = {p.c0:.4g} "
        f"(σVr = {p.sigma_vr_mps:.3g} m/s), seed {p.seed}",
    )
    for alert in result.alerts:
        log_text(rec, alert, level="WARN", scan=max(p.steps, 1))
    return result


def release_streams() -> None:
    """Free the native side of dropped recording streams.

    rerun-sdk 0.41 keeps every native stream (and its two threads, ``RecordingStream`` and
    ``ChunkBatcher``) alive after the Python object is gone until orphans are cleaned up; a
    tuning session makes one stream per run, so without this the thread count grows by two
    per run.
    """
    cleanup = getattr(rr.bindings, "flush_and_cleanup_orphaned_recordings", None)
    if cleanup is not None:
        cleanup()


@dataclass
class RunReport:
    recording_id: str
    params: TuneParams
    figures: dict[str, float]
    result: TuneResult
    ms: float = 0.0


class TuneSession:
    """Validates raw panel values, simulates, logs a new recording to ``grpc_uri`` and keeps
    the last good run and the last error. ``grpc_uri`` None: log to no sink (tests)."""

    def __init__(self, grpc_uri: str | None, echo: bool = False) -> None:
        self.grpc_uri = grpc_uri
        self.echo = echo
        self.last_good: RunReport | None = None
        self.last_error: str | None = None
        self.runs_done = 0
        self.listeners: list[Callable[[TuneSession], None]] = []
        self._lock = threading.Lock()

    def run(self, raw: dict[str, Any]) -> RunReport:
        params = raw if isinstance(raw, TuneParams) else TuneParams.from_raw(raw)
        rid = f"tune-{self.runs_done + 1}-{uuid.uuid4().hex[:8]}"
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=rid)
        try:
            if self.grpc_uri is not None:
                rec.connect_grpc(self.grpc_uri)
            else:
                rec.set_sinks()  # no sink: the data are dropped (tests, benchmarks)
            result = log_tuning_scene(rec, params)
            rec.flush()
        finally:
            with contextlib.suppress(Exception):
                rec.disconnect()
            del rec
            release_streams()
        return RunReport(rid, params, result.figures, result)

    # Coalescer callbacks
    def done(self, raw: Any, report: RunReport, ms: float) -> None:
        report.ms = ms
        with self._lock:
            self.last_good = report
            self.last_error = None
            self.runs_done += 1
        if self.echo:
            p = report.params
            headline = " ".join(f"{k}={v:.6g}" for k, v in sorted(report.figures.items()))
            print(
                f"run {report.recording_id} scene={p.scene} sigma_beta_deg={p.sigma_beta_deg:g} "
                f"c0={p.c0:g} ms={ms:.0f} {headline}",
                flush=True,
            )
        self._notify()

    def error(self, raw: Any, exc: BaseException) -> None:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if not isinstance(exc, ParameterError | ResultError):  # those are one line already
            msg = f"{type(exc).__name__}: {msg}"
        with self._lock:
            self.last_error = msg
            self.runs_done += 1
        if self.echo:
            print(f"error {msg}", flush=True)
        self._notify()

    def _notify(self) -> None:
        for fn in self.listeners:
            try:
                fn(self)
            except Exception as exc:
                print(f"radarviz tune: display update failed: {exc}", file=sys.stderr, flush=True)

    def status_markdown(self) -> str:
        good = self.last_good
        if good is None:
            return "**status:** waiting for the first run …"
        p = good.params
        head = [
            f"**{SCENES[p.scene]}** · run {good.recording_id} · {good.ms:.0f} ms change→flush",
            f"σr {p.sigma_r_m:g} m · σβ {p.sigma_beta_deg:g}° · T {p.period_s:g} s · "
            f"C0 {p.c0:.4g} · {p.runs} runs · seed {p.seed}",
        ]
        # Markdown: table rows and list items stay on consecutive lines, prose lines are
        # paragraphs of their own.
        out: list[str] = []
        for line in [*head, "", *status_lines(good.result)]:
            block = line.startswith(("|", "- "))
            if out and not block and out[-1] != "":
                out.append("")
            out.append(line)
        return "\n".join(out)

    def save(self, directory: Path = RECORDINGS_DIR) -> Path:
        """Write the last good parameters' scene to ``directory`` atomically."""
        good = self.last_good
        if good is None:
            raise ParameterError("nothing to save yet: no run has finished")
        directory.mkdir(parents=True, exist_ok=True)
        path = directory / f"tune-{time.strftime('%Y%m%d-%H%M%S')}-{uuid.uuid4().hex[:6]}.rrd"
        with recording_file(path) as rec:
            log_tuning_scene(rec, good.params)
        del rec
        release_streams()
        return path
