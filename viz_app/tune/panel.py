"""``radarviz tune``: a Viser panel that re-runs the Prosov scene on every change.

One command runs three things, all bound to 127.0.0.1 unless ``--host`` says otherwise:

* a Viser panel (controls, status line, a small 3D view of the geometry),
* a ``rerun --serve-web`` child (gRPC server + web viewer) in its own process group,
* one worker thread that simulates and logs.

Every change of a control only records the newest parameters (:meth:`Coalescer.submit`, under
a lock); the worker runs the newest parameters, and when newer ones arrived during a run it
runs again with the newest only. Each run is logged as a NEW recording id (application id
``radarviz``) to the gRPC server, so the web viewer switches to it.

σVr and C0 are linked by C0 = σr² / (T² σVr²): C0 is the control, σVr follows it (shown
read-only). The Prosov filters use position measurements only, so C0 / σVr describe the radar
(presets RLS1 … RLS6 of the Gorshkov paper) but do not change the simulated tracks.

Bad values (``ParameterError``) are shown as one line in the panel; the last good run stays.
Any other exception in a run is shown the same way and the server keeps going.
"""

from __future__ import annotations

import contextlib
import math
import os
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
from numpy.typing import NDArray

from radarviz.core.experiments.prosov import (
    ALL_METHODS,
    BLOCK_RUNS,
    ProsovScene,
    TrackingConfig,
    prosov_scene,
)
from radarviz.core.finite_memory.fit import PRESETS, c0_ratio
from radarviz.core.params import (
    PARAMETERS,
    ParameterError,
    check,
    check_choice,
    check_int,
    default,
)
from radarviz.core.scenarios.planar import prosov_target
from radarviz.viz_app.rerun import prosov_scene as prosov_views
from radarviz.viz_app.rerun.prosov_scene import METHODS_SHOWN
from radarviz.viz_app.rerun.recording import (
    APPLICATION_ID,
    colour,
    log_text,
    recording_file,
)
from radarviz.viz_app.rerun.scenes import blueprint, scene_figures, text_log_view
from radarviz.viz_app.rerun.viewer import free_port, rerun_executable, viewer_url

LOOPBACK = "127.0.0.1"
#: Largest run count the panel accepts (one block of the Monte Carlo engine).
MAX_TUNE_RUNS = min(5000, BLOCK_RUNS)
#: The panel's tighter upper ends of table parameters (fast re-runs; seeds a number input holds).
TUNE_LIMITS: dict[str, float] = {"runs": MAX_TUNE_RUNS, "seed": 2**32 - 1, "steps": 1000}
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
RECORDINGS_DIR = Path("recordings")


# --------------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TuneParams:
    """What the panel controls. Validated on construction (ParameterError, one line).

    Every numeric field is a ``core.params.PARAMETERS`` entry and is checked against it (with
    the panel's tighter ``TUNE_LIMITS``), so a bad value reads as on the command line:
    ``sigma_r_m must be a finite number in (0, 1e+06] (got -5)``. The panel starts at σβ = 2°
    (where the methods differ visibly) and 200 runs; the rest are the table's defaults.
    ``c0`` is C0 = σr² / (T² σVr²); σVr follows from it (:attr:`sigma_vr_mps`).
    """

    sigma_r_m: float = default("sigma_r_m")
    sigma_beta_deg: float = 2.0
    period_s: float = default("period_s")
    c0: float = default("c0")
    methods: tuple[str, ...] = ALL_METHODS
    runs: int = 200
    seed: int = default("seed")
    steps: int = default("steps")

    def __post_init__(self) -> None:
        for name in ("sigma_r_m", "sigma_beta_deg", "period_s", "c0", "runs", "seed", "steps"):
            check(name, getattr(self, name), high=TUNE_LIMITS.get(name))
        if not self.methods:
            raise ParameterError(f"methods: select at least one of {', '.join(ALL_METHODS)}")
        for m in self.methods:
            check_choice("method", m, ALL_METHODS)

    @property
    def sigma_vr_mps(self) -> float:
        """σVr that gives C0 with this σr and T: σVr = σr / (T √C0)."""
        return self.sigma_r_m / (self.period_s * math.sqrt(self.c0))

    def config(self) -> TrackingConfig:
        return TrackingConfig(
            sigma_r_m=self.sigma_r_m,
            sigma_beta_deg=self.sigma_beta_deg,
            runs=self.runs,
            seed=self.seed,
            target=prosov_target(self.period_s, self.steps),
            methods=self.methods,
        )

    @classmethod
    def from_raw(cls, raw: dict[str, Any]) -> TuneParams:
        """From panel values (floats from number inputs are accepted for integer fields)."""
        kw = dict(raw)
        for name in ("runs", "seed", "steps"):
            v = kw.get(name)
            if isinstance(v, float) and v.is_integer():
                kw[name] = int(v)
        if "methods" in kw:
            kw["methods"] = tuple(kw["methods"])
        return cls(**kw)


def preset_values(name: str) -> dict[str, float]:
    """σr, T and C0 (from σVr) of a Gorshkov radar preset RLS1 … RLS6."""
    p = PRESETS[check_choice("preset", name, PRESETS)]
    return {
        "sigma_r_m": p.sigma_r_m,
        "period_s": p.period_s,
        "c0": c0_ratio(sigma_r_m=p.sigma_r_m, sigma_vr_mps=p.sigma_vr_mps, period_s=p.period_s),
    }


# --------------------------------------------------------------------------------------------
# Simulation and logging
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TuneResult:
    """One run of the panel: its parameters and the Prosov scene core made of them."""

    params: TuneParams
    scene: ProsovScene

    def figures(self) -> dict[str, float]:
        """Key figures at the last scan, named like ``log_prosov``'s."""
        return scene_figures(self.scene)


def simulate(params: TuneParams) -> TuneResult:
    """The Prosov scene of ``params`` (``core.experiments.prosov.prosov_scene``).

    The statistics are ``run_tracking``'s (``core.metrics``) and the displayed run is the one
    ``radarviz record --preset prosov`` and ``radarviz demo`` draw for the same seed and σ.
    """
    return TuneResult(params, prosov_scene(params.config()))


_BLUEPRINT: list[Any] = []
_BLUEPRINT_LOCK = threading.Lock()
#: Converted points per scan behind each cloud mean the panel draws.
TUNE_CLOUD_POINTS = 1000


def send_blueprint(rec: rr.RecordingStream) -> None:
    """Send the tuning blueprint (the Prosov tab), built once.

    The Prosov views' bounds do not depend on the parameters (the scene's transforms carry
    the scale), so one blueprint serves every run. ``rec.send_blueprint`` builds a new
    in-memory blueprint stream on every call, and rerun-sdk 0.41 never frees it (two native
    threads each); reusing the built storage keeps the thread count flat over any number of
    runs.
    """
    from rerun.blueprint.api import create_in_memory_blueprint

    with _BLUEPRINT_LOCK:
        if not _BLUEPRINT:
            bp = blueprint(
                prosov_views.views(METHODS_SHOWN), rrb.Vertical(text_log_view(), name="log")
            )
            storage = create_in_memory_blueprint(application_id=APPLICATION_ID, blueprint=bp)
            _BLUEPRINT.append(storage.storage)
        storage = _BLUEPRINT[0]
    rr.bindings.send_blueprint(storage, True, True, recording=rec.to_native())


def log_tuning_scene(rec: rr.RecordingStream, params: TuneParams) -> TuneResult:
    """Simulate ``params`` and log the Prosov scene (``prosov_scene.log_scene``: the map, the
    target frame of every method, the Monte Carlo statistics) and its blueprint.

    Returns the simulation result (``result.figures()`` are the key figures for the status
    line).
    """
    result = simulate(params)
    p = params
    prosov_views.log_scene(rec, result.scene, TUNE_CLOUD_POINTS)
    send_blueprint(rec)
    log_text(
        rec,
        f"tune: {p.runs} Monte Carlo runs × {p.steps} scans, σr = {p.sigma_r_m:g} m, "
        f"σβ = {p.sigma_beta_deg:g}°, T = {p.period_s:g} s, C0 = {p.c0:.4g} "
        f"(σVr = {p.sigma_vr_mps:.3g} m/s), seed {p.seed}",
    )
    return result


# --------------------------------------------------------------------------------------------
# Coalescing worker
# --------------------------------------------------------------------------------------------


class Coalescer:
    """One worker thread that runs ``fn`` on the newest submitted item only.

    ``submit`` just stores the item (and its submit time) under the lock and notifies. The
    worker takes the newest item, runs ``fn`` outside the lock, then ``on_done(item, result,
    ms)`` with ``ms`` the time from that item's submission to the end of the run, or
    ``on_error(item, exc)`` on any exception (the worker keeps going).
    """

    def __init__(
        self,
        fn: Callable[[Any], Any],
        on_done: Callable[[Any, Any, float], None] | None = None,
        on_error: Callable[[Any, BaseException], None] | None = None,
        name: str = "radarviz-tune-worker",
    ) -> None:
        self._fn = fn
        self._on_done = on_done
        self._on_error = on_error
        self._cond = threading.Condition()
        self._pending: tuple[Any, float] | None = None
        self._busy = False
        self._stopping = False
        self.submitted = 0
        self.completed = 0  # runs finished, successful or not
        self.last_item: Any = None
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any) -> None:
        with self._cond:
            self._pending = (item, time.perf_counter())
            self.submitted += 1
            self._cond.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Wait until nothing is pending or running; False on timeout."""
        with self._cond:
            return self._cond.wait_for(
                lambda: (self._pending is None and not self._busy) or self._stopping, timeout
            )

    def stop(self, timeout: float = 10.0) -> None:
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _loop(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._pending is not None or self._stopping)
                if self._stopping:
                    return
                assert self._pending is not None
                item, t0 = self._pending
                self._pending = None
                self._busy = True
            try:
                try:
                    result = self._fn(item)
                except Exception as exc:  # never let a bad run stop the worker
                    if self._on_error is not None:
                        self._on_error(item, exc)
                else:
                    if self._on_done is not None:
                        self._on_done(item, result, (time.perf_counter() - t0) * 1e3)
            except Exception as exc:  # a failing callback must not stop the worker either
                print(f"radarviz tune: callback failed: {exc}", file=sys.stderr, flush=True)
            finally:
                with self._cond:
                    self._busy = False
                    self.completed += 1
                    self.last_item = item
                    self._cond.notify_all()


# --------------------------------------------------------------------------------------------
# A session: params → new recording on the gRPC server
# --------------------------------------------------------------------------------------------


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
        return RunReport(rid, params, result.figures(), result)

    # Coalescer callbacks
    def done(self, raw: Any, report: RunReport, ms: float) -> None:
        report.ms = ms
        with self._lock:
            self.last_good = report
            self.last_error = None
            self.runs_done += 1
        if self.echo:
            print(
                f"run {report.recording_id} sigma_beta_deg={report.params.sigma_beta_deg:g} "
                f"ms={ms:.0f}",
                flush=True,
            )
        self._notify()

    def error(self, raw: Any, exc: BaseException) -> None:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if not isinstance(exc, ParameterError):
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
        lines = [
            f"**run {good.recording_id}** · {good.ms:.0f} ms change→flush · "
            f"σr {p.sigma_r_m:g} m · σβ {p.sigma_beta_deg:g}° · T {p.period_s:g} s · "
            f"C0 {p.c0:.4g} · {p.runs} runs · seed {p.seed}",
            "",
            "| method | bias range (m) | NEES pos |",
            "|---|---:|---:|",
        ]
        for m in p.methods:
            lines.append(
                f"| {m} | {good.figures[f'{m}.bias_range_m']:.1f} "
                f"| {good.figures[f'{m}.nees_pos']:.2f} |"
            )
        lo, hi = good.result.scene.result.nees_pos_band95
        lines.append("")
        lines.append(f"last scan; NEES 95% band [{lo:.2f}, {hi:.2f}]")
        return "\n".join(lines)

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


# --------------------------------------------------------------------------------------------
# Viser panel
# --------------------------------------------------------------------------------------------


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
    """The Viser controls, status line, error line and geometry view."""

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
        gui.add_markdown("## radarviz tune — Prosov scene")
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
        self.sigma_vr = gui.add_number(
            "σVr (m/s) = σr/(T√C0)", round(p.sigma_vr_mps, 4), disabled=True
        )
        gui.add_markdown("**methods shown**")
        self.methods = {m: gui.add_checkbox(m, m in p.methods) for m in ALL_METHODS}
        self.save_button = gui.add_button("save recording")
        self.error_md = gui.add_markdown("")
        self.status_md = gui.add_markdown(session.status_markdown())
        self._steps = p.steps
        for h in (
            self.sigma_r,
            self.sigma_beta,
            self.period,
            self.c0,
            self.runs,
            self.seed,
            *self.methods.values(),
        ):
            h.on_update(self._changed)
        self.preset.on_update(self._preset_changed)
        self.save_button.on_click(self._save)
        session.listeners.append(self.refresh)
        server.scene.add_icosphere("/radar", radius=0.8, color=(0, 0, 0))
        with contextlib.suppress(Exception):  # look down on radar and target path (km)
            cam = server.initial_camera
            cam.look_at = (80.0, 0.0, 0.0)
            cam.position = (80.0, -60.0, 180.0)
            cam.far = 10_000.0

    def raw(self) -> dict[str, Any]:
        return {
            **{name: h.value for name, h in self.controls.items()},
            "steps": self._steps,
            "methods": tuple(m for m, h in self.methods.items() if h.value),
        }

    def _changed(self, _event: Any = None) -> None:
        raw = self.raw()
        with contextlib.suppress(Exception):  # σVr display only; bad values are shown later
            self.sigma_vr.value = round(
                float(raw["sigma_r_m"]) / (float(raw["period_s"]) * math.sqrt(raw["c0"])), 4
            )
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
        good = session.last_good
        if good is not None and err is None:
            self._draw(good.result)

    def _draw(self, result: TuneResult) -> None:
        """Geometry in km: radar (origin), truth path, the displayed run's measurements and
        tracks."""
        scene = self.server.scene
        km = 1e-3

        def segments(xy: NDArray) -> NDArray:
            p = np.zeros((len(xy), 3), dtype=np.float32)
            p[:, :2] = xy * km
            return np.stack([p[:-1], p[1:]], axis=1)

        shown = result.scene
        scene.add_line_segments(
            "/truth", segments(shown.truth[:, [0, 2]]), (20, 20, 20), thickness=0.6
        )
        measured = shown.converted_xy_m["naive"]
        meas = np.zeros((len(measured), 3), dtype=np.float32)
        meas[:, :2] = measured * km
        scene.add_point_cloud("/measurements", meas, (90, 90, 90), point_size=0.8)
        for m in ALL_METHODS:
            if m in shown.tracks:
                x = shown.tracks[m].x
                scene.add_line_segments(
                    f"/tracks/{m}", segments(x[:, [0, 2]]), colour(m), thickness=0.4
                )
            else:
                with contextlib.suppress(Exception):
                    scene.remove_by_name(f"/tracks/{m}")


# --------------------------------------------------------------------------------------------
# Servers and the command
# --------------------------------------------------------------------------------------------


def grpc_uri(host: str, port: int) -> str:
    connect = LOOPBACK if host in ("0.0.0.0", "::", "") else host
    return f"rerun+http://{connect}:{port}/proxy"


def wait_port(host: str, port: int, timeout: float = 30.0) -> None:
    connect = LOOPBACK if host in ("0.0.0.0", "::", "") else host
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        with contextlib.suppress(OSError), socket.create_connection((connect, port), timeout=1):
            return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on {connect}:{port} after {timeout:g} s")


def start_rerun(host: str, grpc_port: int, web_port: int | None) -> subprocess.Popen:
    """``rerun --serve-web`` (or ``--serve-grpc`` when ``web_port`` is None) in its own
    process group, bound to ``host``."""
    cmd = [rerun_executable()]
    cmd += (
        ["--serve-grpc"]
        if web_port is None
        else ["--serve-web", "--web-viewer-port", str(web_port)]
    )
    cmd += ["--bind", host, "--port", str(grpc_port), "--server-memory-limit", "512MiB"]
    env = {**os.environ, "RERUN_ANALYTICS": "0"}
    return subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True, env=env
    )


def stop_process_group(proc: subprocess.Popen | None) -> None:
    if proc is None or proc.poll() is not None:
        return
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=5)


def measure_tune_latency(changes: int = 10, runs: int = 200, steps: int = 60) -> float:
    """Median ms from a parameter change to the recording flushed to a local gRPC server.

    Starts ``rerun --serve-grpc`` on 127.0.0.1, then submits ``changes`` σβ changes one
    after another through the same worker path as the panel (one warm-up run first).
    """
    port = free_port(LOOPBACK)
    proc = start_rerun(LOOPBACK, port, None)
    times: list[float] = []
    worker = None
    try:
        wait_port(LOOPBACK, port)
        session = TuneSession(grpc_uri(LOOPBACK, port))
        worker = Coalescer(
            session.run,
            lambda raw, rep, ms: times.append(ms),
            lambda raw, exc: times.append(float("nan")),
        )
        base = TuneParams(runs=runs, steps=steps)
        worker.submit(base)
        worker.wait_idle(120)
        times.clear()
        for i in range(changes):
            worker.submit(replace(base, sigma_beta_deg=1.0 + 0.1 * (i % 10)))
            worker.wait_idle(120)
    finally:
        if worker is not None:
            worker.stop()
        stop_process_group(proc)
    return float(statistics.median(times)) if times else float("nan")


def cmd_tune(
    host: str = LOOPBACK, port: int = 0, viewer_port: int = 0, no_browser: bool = False
) -> int:
    """Run the panel, the gRPC server and the web viewer until SIGTERM / Ctrl-C."""
    import viser

    from radarviz.viz_app.runtime import tune_allocator

    check_int("--port", port, low=0, high=65535)
    check_int("--viewer-port", viewer_port, low=0, high=65535)
    if host != LOOPBACK:
        print(
            f"radarviz: warning: binding {host}: the tuning panel and viewer are reachable "
            "from other machines",
            file=sys.stderr,
            flush=True,
        )
    tune_allocator()

    def _stop(signum: int, frame: object) -> None:
        raise SystemExit(0)  # unwinds into the finally below

    signal.signal(signal.SIGTERM, _stop)
    bind_probe = LOOPBACK if host in ("0.0.0.0", "::", "") else host
    grpc_port = free_port(bind_probe)
    web_port = viewer_port or free_port(bind_probe)
    proc = None
    server = None
    worker = None
    try:
        proc = start_rerun(host, grpc_port, web_port)
        server = viser.ViserServer(host=host, port=port, verbose=False)
        session = TuneSession(grpc_uri(host, grpc_port), echo=True)
        worker = Coalescer(session.run, session.done, session.error)
        panel = TunePanel(server, session, worker)
        wait_port(host, grpc_port)
        panel_url = f"http://{bind_probe}:{server.get_port()}/"
        view_url = viewer_url(bind_probe, web_port, grpc_port)
        print(f"panel {panel_url}", flush=True)
        print(f"viewer {view_url}", flush=True)
        print("stop with Ctrl-C", flush=True)
        worker.submit(panel.raw())
        if not no_browser:
            import webbrowser

            webbrowser.open(panel_url)
            webbrowser.open(view_url)
        while True:
            time.sleep(0.5)
            if proc.poll() is not None:
                print("radarviz: error: the rerun viewer stopped", file=sys.stderr, flush=True)
                return 1
    except (KeyboardInterrupt, SystemExit):
        return 0
    finally:
        if worker is not None:
            worker.stop()
        if server is not None:
            with contextlib.suppress(Exception):
                server.stop()
        stop_process_group(proc)
