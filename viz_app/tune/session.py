"""A tuning session: panel values → a new recording on the gRPC server, per run.

Each run is logged as a NEW recording id (application id ``radarviz``) so the web viewer
switches to it; the last good run and the last error are kept, and listeners (the panel) are
told after every run. Bad values (``ParameterError``) and results that are not finite
(``ResultError``: a NaN, a negative NEES) become the error line; the last good run stays on
screen.

A run has two stages (the worker's ``prepare`` and ``fn``): :meth:`TuneSession.prepare`
simulates and logs the whole run into a recording stream with no sink yet (the SDK keeps it
in memory); :meth:`TuneSession.commit` connects that stream to the viewer's server, which
then sends the run in one burst. Why: the viewer takes in what has arrived at the start of
each of its frames (a few hundred ms each with software WebGL), so a run streamed while it is
being logged is drawn in parts over several frames. :meth:`TuneSession.discard` drops a
prepared run that a newer change overtook during the panel's settling pause.
"""

from __future__ import annotations

import contextlib
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import Chunk

from radarviz.core.finite import ResultError
from radarviz.core.params import ParameterError
from radarviz.viz_app.rerun import gorshkov_scene, prosov_scene, velocity_scene
from radarviz.viz_app.rerun.recording import APPLICATION_ID, log_texts, recording_file
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
_BLUEPRINTS: dict[str, list[Chunk]] = {}
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


def _blueprint_stream() -> rr.RecordingStream:
    """A new blueprint stream of the application (a fresh blueprint id), logging to memory
    only when told (``memory_recording``); disconnect it when done, which ends its threads."""
    from rerun.recording_stream import RecordingStream

    return RecordingStream._from_native(
        rr.bindings.new_blueprint(
            application_id=APPLICATION_ID,
            make_default=False,
            make_thread_default=False,
            default_enabled=True,
        )
    )


def blueprint_chunks(scene: str) -> list[Chunk]:
    """The chunks of the scene's blueprint, built once per scene (a few hundred ms) and kept.

    The blueprint is logged as ``rerun.blueprint.api.create_in_memory_blueprint`` does, into
    a memory sink whose bytes are read back as chunks (``RrdReader`` reads files only: a
    temporary one, removed at once). Chunks carry no store id: :func:`send_blueprint` puts
    them into a new blueprint store each time.
    """
    from rerun.chunk import RrdReader

    with _BLUEPRINT_LOCK:
        chunks = _BLUEPRINTS.get(scene)
        if chunks is None:
            stream = _blueprint_stream()
            try:
                memory = stream.memory_recording()
                stream.set_time("blueprint", sequence=0)
                scene_blueprint(scene).to_blueprint()._log_to_stream(stream)
                data = memory.drain_as_bytes()
            finally:
                with contextlib.suppress(Exception):
                    stream.disconnect()
            with tempfile.TemporaryDirectory(prefix="radarviz-blueprint-") as tmp:
                path = Path(tmp) / f"{scene}.rrd"
                path.write_bytes(data)
                reader = RrdReader(path)
                (store,) = reader.blueprints()
                chunks = _BLUEPRINTS[scene] = list(reader.stream(store=store))
    return chunks


def prepare_blueprints() -> None:
    """Build every scene's blueprint now, so that no run (the first switch to a scene
    included) waits for one."""
    for scene in SCENES:
        blueprint_chunks(scene)


def send_blueprint(rec: rr.RecordingStream, scene: str) -> None:
    """Send the scene's blueprint with ``rec``, as a NEW blueprint store, made active.

    Every run carries its whole blueprint under a fresh blueprint id, for two reasons:

    - the viewer switches layout only on a blueprint it activates: a blueprint it has seen
      before (prosov → velocity → prosov) or none at all leaves it on the previous scene's
      views, which then show "No data available";
    - a viewer opened later gets only what the gRPC server still buffers
      (``serve.SERVER_MEMORY_LIMIT`` drops the oldest runs): the newest run must carry its
      own blueprint.

    The SDK's ``send_blueprint`` drains the storage it is given (a storage sent twice sends
    nothing the second time), and building the blueprint anew each run would cost hundreds of
    ms; so the scene's chunks are built once (:func:`blueprint_chunks`) and copied into a new
    blueprint stream per run (≈ 10–30 ms), which is disconnected afterwards so its native
    threads end with it.
    """
    chunks = blueprint_chunks(scene)
    stream = _blueprint_stream()
    try:
        memory = stream.memory_recording()
        stream.send_chunks(chunks)
        rr.bindings.send_blueprint(memory.storage, True, True, recording=rec.to_native())
    finally:
        with contextlib.suppress(Exception):
            stream.disconnect()


def log_tuning_scene(
    rec: rr.RecordingStream, params: TuneParams, series: bool = True, blueprint: bool = True
) -> TuneResult:
    """Simulate ``params`` and log its blueprint and scene (the viewer's scene module).

    ``series``: with the statistics' values under ``plots/`` as well as their charts. The
    panel's runs leave them out: no view draws them, and the viewer's time to a run's first
    complete frame grows with the chunks it must take in (a saved run keeps them).
    ``blueprint``: send the scene's blueprint first (a saved run, and a panel run that
    switches scene); without it the viewer keeps the layout it shows."""
    result = simulate(params)
    if blueprint:
        send_blueprint(rec, params.scene)
    log_result(rec, result, series)
    p = params
    head = (
        f"tune {p.scene}: {p.runs} runs × {p.steps} scans, σr = {p.sigma_r_m:g} m, "
        f"σβ = {p.sigma_beta_deg:g}°, T = {p.period_s:g} s, C0 = {p.c0:.4g} "
        f"(σVr = {p.sigma_vr_mps:.3g} m/s), seed {p.seed}"
    )
    # One chunk for the lot (each is one more message for the viewer to take in).
    last = max(p.steps, 1)
    alerts = [(last, (last - 1) * p.period_s, alert, "WARN") for alert in result.alerts]
    log_texts(rec, [(1, 0.0, head, "INFO"), *alerts])
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
class PreparedRun:
    """A run logged into ``rec`` (no sink yet: held in memory), not yet sent; ``rec`` is
    None once it is closed, ``result`` None until the run is logged."""

    recording_id: str
    params: TuneParams
    rec: rr.RecordingStream | None
    result: TuneResult | None = None

    def close(self) -> None:
        """Disconnect the stream (what it has not sent is dropped), let it go and free its
        native threads (:func:`release_streams` frees only streams no object holds)."""
        rec, self.rec = self.rec, None
        if rec is not None:
            with contextlib.suppress(Exception):
                rec.disconnect()
            del rec
            release_streams()


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
        #: The scene whose blueprint the viewer was last sent (runs of the same scene send
        #: none: the viewer keeps its layout instead of building it anew).
        self.blueprint_scene: str | None = None
        self.listeners: list[Callable[[TuneSession], None]] = []
        self._lock = threading.Lock()

    def run(self, raw: dict[str, Any] | TuneParams) -> RunReport:
        """Prepare and commit at once (no settling pause)."""
        return self.commit(self.prepare(raw))

    def prepare(self, raw: dict[str, Any] | TuneParams) -> PreparedRun:
        """Check the values, simulate, and log the run into a stream with no sink yet (a
        ``ParameterError`` or ``ResultError`` for bad values, nothing kept)."""
        params = raw if isinstance(raw, TuneParams) else TuneParams.from_raw(raw)
        rid = f"tune-{self.runs_done + 1}-{uuid.uuid4().hex[:8]}"
        # The stream holds what is logged until it is connected (``commit``).
        rec = rr.RecordingStream(APPLICATION_ID, recording_id=rid)
        run = PreparedRun(rid, params, rec)
        try:
            # The blueprint goes with a run that changes scene from the one the viewer shows;
            # ``blueprint_scene`` moves only when a run is sent (a discarded run sent none).
            switch = params.scene != self.blueprint_scene
            run.result = log_tuning_scene(rec, params, series=False, blueprint=switch)
            # Into the stream's buffer now: a run committed before the SDK's own flush tick
            # would otherwise reach the viewer in two parts (two frames to draw, not one).
            rec.flush()
        except BaseException:
            del rec  # the run's close frees the stream only once nothing else holds it
            run.close()
            raise
        return run

    def commit(self, run: PreparedRun) -> RunReport:
        """Send a prepared run to the viewer's server (at once, in one burst) and close it."""
        rec, result = run.rec, run.result
        assert rec is not None and result is not None, "a prepared run is sent once"
        try:
            if self.grpc_uri is not None:
                rec.connect_grpc(self.grpc_uri)  # sends what the stream holds
            else:
                rec.set_sinks()  # no sink: the data are dropped (tests, benchmarks)
            rec.flush()
            self.blueprint_scene = run.params.scene
        finally:
            del rec
            run.close()
        return RunReport(run.recording_id, run.params, result.figures, result)

    def discard(self, run: PreparedRun) -> None:
        """Drop a prepared run unsent (a newer change overtook it)."""
        run.close()

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
