"""``radarviz bench``, section ``live``: a feed replayed into ``radarviz live`` and its latency.

The scene: the association section's rotating radars (``viz_app.bench.association``: four
radars 113 km apart, periods 4.0 to 5.1 s, each plot stamped by its beam) over ``targets``
targets of air traffic, written (not timed) as an ASTERIX file of data blocks of
``BLOCK_RECORDS`` records, a datagram each as a feed sends a sector's plots. Its first
``rate_plots_per_s × seconds`` plots are replayed (``viz_app.live.replay.paced``) to
127.0.0.1 at the speed that makes them ``rate_plots_per_s`` plots a second, into
``radarviz live --udp … --method ucm`` in its own process, with its web viewer (a
``rerun --serve-web`` server on loopback the recording streams to, no browser attached)
unless ``viewer`` is False. The figures are the session's own summary (``--summary``):

* ``sent_plots`` and ``sent_datagrams`` (what the replay sent; ``refused_datagrams``: sends
  the port refused, 0 unless the live process stopped listening), ``tracked``, ``dropped``
  (the bounded queue full), ``out_of_order``, ``malformed`` (datagrams and records refused),
  ``duplicates`` (byte-identical records passed over) and ``untracked_at_stop``: every plot
  accounted for;
* ``latency_median_ms`` and ``latency_p99_ms``: from a datagram's arrival to its plots'
  rows handed to the recording and flushed, the viewer's logging included;
* ``peak_rss_mb``: the live process's peak resident set (the viewer's server apart);
* ``latency_parts_median_ms``: the median of each part of the latency
  (``viz_app.live.session.LATENCY_PARTS``: queue, order, wait, run, flush).

The soak (``radarviz bench --only live --live-soak-s 600``, not in CI) is the same run made
``soak_s`` long, with the live process's resident set read every ``SOAK_SAMPLE_S`` (its
``/proc`` status). After a warm-up (``SOAK_WARMUP_FRACTION`` of the run: the book's arrays
reach the scene's track count, the kernels and the recording stream their working size),
the samples are averaged in ``SOAK_BLOCKS`` consecutive blocks and a line is fitted to the
block means (:func:`memory_trend`): the slope in MiB per hour and its standard error. Means
of blocks a minute long are close to independent where single samples seconds apart are
not (the allocator's steps), so the error is honest. Memory is called flat when the slope is
within two standard errors of zero, or below ``FLAT_FRACTION_PER_H`` of the resident set
per hour (a growth too slow to matter over a day).
"""

from __future__ import annotations

import json
import math
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

import numpy as np

#: Plots a second of the replay, and its seconds (``radarviz bench --live-rate``,
#: ``--live-seconds``).
DEFAULT_RATE = 2000.0
DEFAULT_SECONDS = 20.0
#: Targets of the scene (``radarviz bench --live-targets``).
DEFAULT_TARGETS = 300
#: Records of a data block (one datagram) of the replayed file.
BLOCK_RECORDS = 16
#: How long ``live`` may take to start (its viewer, its kernels) and to end after the feed.
START_S, END_S = 120.0, 120.0
#: The soak's sampling period (s), share of the run taken as warm-up, and blocks of the fit.
SOAK_SAMPLE_S = 2.0
SOAK_WARMUP_FRACTION = 0.2
SOAK_BLOCKS = 12
#: A growth per hour below this share of the resident set is called flat.
FLAT_FRACTION_PER_H = 0.01


def rss_mib(pid: int) -> float | None:
    """The resident set of process ``pid`` now (MiB), None once it is gone."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        return None
    return None


#: The bench's figures that may be below zero (``check_finite_document``'s ``signed``): a
#: soak's memory slope, negative when the resident set shrinks after its warm-up.
SIGNED_FIGURES = ("slope_mib_per_h",)


def memory_trend(
    times_s: list[float], rss: list[float], warmup_s: float, blocks: int = SOAK_BLOCKS
) -> dict[str, Any]:
    """The line fitted to the block means of the samples after ``warmup_s`` (module
    docstring): slope and standard error (MiB/h), the mean resident set after the warm-up
    (MiB), the samples used, and whether memory is flat."""
    t = np.asarray(times_s, dtype=np.float64)
    m = np.asarray(rss, dtype=np.float64)
    keep = t >= warmup_s
    t, m = t[keep], m[keep]
    if t.size < 2 * blocks:
        raise ValueError(f"the soak needs at least {2 * blocks} samples after its warm-up")
    edges = np.linspace(t[0], t[-1], blocks + 1)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, blocks - 1)
    bt = np.array([t[which == b].mean() for b in range(blocks)]) / 3600.0
    bm = np.array([m[which == b].mean() for b in range(blocks)])
    dt = bt - bt.mean()
    slope = float(dt @ (bm - bm.mean()) / (dt @ dt))
    resid = bm - bm.mean() - slope * dt
    se = float(np.sqrt(resid @ resid / (blocks - 2) / (dt @ dt)))
    mean = float(m.mean())
    flat = abs(slope) <= 2.0 * se or slope <= FLAT_FRACTION_PER_H * mean
    return {
        "slope_mib_per_h": slope,
        "slope_se_mib_per_h": se,
        "rss_after_warmup_mib": mean,
        "samples": int(t.size),
        "flat": bool(flat),
    }


#: Half the side of the soak's square of traffic (m): the four radars' sites and a margin.
SOAK_HALF_WIDTH_M = 70e3


def bouncing_traffic(
    rng: np.random.Generator,
    targets: int,
    duration_s: float,
    half_width_m: float = SOAK_HALF_WIDTH_M,
    speed_mps: tuple[float, float] = (150.0, 250.0),
    step_s: float = 1.0,
) -> Any:
    """The soak's traffic: ``targets`` straight flights at constant speed that turn back at
    the sides of a square (a reflection), so the scene keeps its density for hours where the
    section's air traffic, flying across the radars' disc, has left it after ten minutes.
    Sampled every ``step_s``: between two samples a flight is straight but at a reflection,
    where ``Traffic.at`` cuts the corner (a turn of a second)."""
    from radarviz.core.scenarios.rotating import Traffic

    t = np.arange(math.ceil(duration_s / step_s) + 1) * step_s
    start = rng.uniform(-half_width_m, half_width_m, (targets, 2))
    heading = rng.uniform(0.0, 2 * math.pi, targets)
    v = rng.uniform(*speed_mps, targets)[:, None] * np.stack([np.cos(heading), np.sin(heading)], -1)
    # Unfolded straight line, folded into [-w, w] by a triangle wave (period 4w).
    w = half_width_m
    u = start[None, :, :] + v[None, :, :] * t[:, None, None] + w
    phase = np.mod(u, 4 * w)
    position = np.where(phase < 2 * w, phase, 4 * w - phase) - w
    velocity = np.where(phase < 2 * w, 1.0, -1.0) * v[None, :, :]
    return Traffic(t, position, velocity)


def live_scene(
    tmp: str, targets: int, plots: int, seed: int = 5, soak: bool = False
) -> tuple[str, str, int, float]:
    """The section's file (module docstring) with at least ``plots`` plots where the scene
    has them: its path, the radars file, the plots written and their span of feed time (s).
    ``soak``: the traffic of ``bouncing_traffic``, which keeps the plots coming for hours."""
    from radarviz.core.experiments.association import rotating_scene_plots
    from radarviz.core.scenarios.rotating import RotatingRadar, air_traffic, rotating_plots
    from radarviz.viz_app.bench.association import ROTATING_SITES
    from radarviz.viz_app.io import asterix as ax
    from radarviz.viz_app.io.plots import Radar

    sites = [
        RotatingRadar(f"r{j}", x, y, period_s=4.0 + 0.37 * j, phase_rad=1.3 * j)
        for j, (x, y) in enumerate(ROTATING_SITES)
    ]
    # About half the targets are in a radar's coverage at any time, each seen by about two
    # radars a revolution: a scene lasts the plots over that rate, and a little more.
    per_s = max(0.2 * targets, 1.0)
    duration_s = 1.2 * plots / per_s + 10.0
    rng = np.random.default_rng(seed)
    if soak:
        # Measured: about 0.45 plots a second per target of the square, clutter included.
        duration_s = 1.2 * plots / max(0.4 * targets, 1.0) + 10.0
        traffic = bouncing_traffic(rng, targets, duration_s)
    else:
        traffic = air_traffic(rng, targets, duration_s, turn_deg=60.0, turn_rate_dps=1.5)
    scene = rotating_scene_plots(sites, rotating_plots(rng, sites, traffic, duration_s))
    scene = scene[:plots]
    radars = [
        Radar(s.name, s.x_m, s.y_m, 0.0, s.sigma_r_m, math.degrees(s.sigma_beta_rad)) for s in sites
    ]
    ast, toml = os.path.join(tmp, "feed.ast"), os.path.join(tmp, "radars.toml")
    ax.write_asterix(ast, toml, scene, radars, block_records=BLOCK_RECORDS)
    return ast, toml, len(scene), scene[-1].time_s - scene[0].time_s


def free_udp_port(host: str) -> int:
    """A currently free UDP port on ``host`` (bind to port 0, read it, close)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def bench_live(
    rate_plots_per_s: float = DEFAULT_RATE,
    seconds: float = DEFAULT_SECONDS,
    targets: int = DEFAULT_TARGETS,
    viewer: bool = True,
    soak: bool = False,
) -> dict[str, Any]:
    """The ``live`` figures (module docstring); ``soak``: the live process's resident set
    sampled through the run, and its trend (``memory``)."""
    from radarviz.viz_app.live.replay import (
        Address,
        ReplayCounts,
        paced,
        recorded_feed,
        udp_sender,
    )

    wanted = max(round(rate_plots_per_s * seconds), 1)
    with tempfile.TemporaryDirectory(prefix="radarviz-bench-live-") as tmp:
        ast, toml, plots, span_s = live_scene(tmp, targets, wanted, soak=soak)
        speed = rate_plots_per_s * span_s / max(plots, 1) if span_s > 0 else 1.0
        port = free_udp_port("127.0.0.1")
        summary = os.path.join(tmp, "live.json")
        argv = [sys.executable, "-m", "radarviz.viz_app.cli.main", "live"]
        argv += ["--udp", f"127.0.0.1:{port}", "--radars", toml, "--method", "ucm"]
        argv += ["--max-plots", str(plots), "--summary", summary]
        argv += ["--duration-s", f"{START_S + plots / rate_plots_per_s + END_S:.0f}"]
        if not viewer:
            argv.append("--no-viewer")
        live = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        try:
            assert live.stderr is not None
            said: list[str] = []
            while True:
                line = live.stderr.readline()
                if not line:
                    raise RuntimeError(f"radarviz live did not start: {''.join(said)}")
                said.append(line)
                if "tracking udp" in line:
                    break
            sock, send = udp_sender(Address("127.0.0.1", port))
            start = time.monotonic()
            samples: tuple[list[float], list[float]] = ([], [])
            done = threading.Event()

            def sample() -> None:
                while not done.wait(SOAK_SAMPLE_S):
                    got = rss_mib(live.pid)
                    if got is not None:
                        samples[0].append(time.monotonic() - start)
                        samples[1].append(got)

            sampler = threading.Thread(target=sample, name="soak-rss", daemon=True)
            if soak:
                sampler.start()
            with sock, open(ast, "rb") as fh:
                sent: ReplayCounts = paced(recorded_feed(fh, ast), speed, send)
            replay_s = time.monotonic() - start
            done.set()
            err = live.stderr.read()
            if live.wait(timeout=START_S + END_S) != 0:
                raise RuntimeError(f"radarviz live failed: {err}")
        finally:
            if live.poll() is None:
                live.kill()
                live.wait()
        with open(summary, encoding="utf-8") as fh:
            doc = json.load(fh)
    lat = doc["latency_ms"]
    out: dict[str, Any] = {
        "viewer": viewer,
        "targets": targets,
        "rate_plots_per_s": rate_plots_per_s,
        "replay_s": replay_s,
        "speed": speed,
        "sent_datagrams": sent.datagrams,
        "refused_datagrams": sent.refused,
        "sent_plots": plots,
        "tracked": doc["tracked"],
        "dropped": doc["dropped"],
        "out_of_order": doc["out_of_order"],
        "malformed": sum(doc["malformed"].values()),
        "duplicates": doc["duplicate_records"],
        "untracked_at_stop": doc["untracked_at_stop"],
        "latency_median_ms": lat["median"],
        "latency_p99_ms": lat["p99"],
        "peak_rss_mb": doc["peak_rss_mb"],
        "latency_parts_median_ms": doc.get("latency_parts_ms", {}),
    }
    if soak:
        out["memory"] = memory_trend(*samples, SOAK_WARMUP_FRACTION * replay_s)
    return out


def format_live(doc: dict[str, Any]) -> str:
    """One line of ``format_bench``."""
    where = "with its web viewer" if doc["viewer"] else "without a viewer"
    lat = (
        f"latency median {doc['latency_median_ms']:.0f} ms, p99 {doc['latency_p99_ms']:.0f} ms"
        if doc["latency_median_ms"] is not None
        else "no plot tracked"
    )
    n_refused = doc.get("refused_datagrams", 0)
    refused = f", {n_refused} datagrams refused" if n_refused else ""
    return (
        f"live: {doc['sent_plots']} plots of {doc['targets']} targets and 4 radars replayed "
        f"to 127.0.0.1 at {doc['rate_plots_per_s']:.0f} plots/s ({doc['replay_s']:.1f} s{refused}) "
        f"into radarviz live --method ucm {where}: {doc['tracked']} tracked, "
        f"{doc['dropped']} dropped, {doc['out_of_order']} out of order, {doc['malformed']} "
        f"malformed, {doc.get('duplicates', 0)} duplicate, {doc['untracked_at_stop']} "
        f"untracked at the stop; {lat}; peak RSS "
        f"{doc['peak_rss_mb']:.0f} MiB{format_parts(doc['latency_parts_median_ms'])}"
    ) + (format_memory(doc["memory"]) if "memory" in doc else "")


def format_parts(parts: dict[str, float | None]) -> str:
    """Where the latency goes (``viz_app.live.session.LATENCY_PARTS``), medians in ms."""
    shown = [f"{k} {v:.0f}" for k, v in parts.items() if v is not None]
    return f" (median ms of its parts: {', '.join(shown)})" if shown else ""


def format_memory(m: dict[str, Any]) -> str:
    """The soak's words (module docstring)."""
    verdict = "flat" if m["flat"] else "GROWING"
    return (
        f"; memory {verdict}: {m['slope_mib_per_h']:+.1f} ± {m['slope_se_mib_per_h']:.1f} "
        f"MiB/h (1σ) over {m['samples']} samples after the warm-up, resident "
        f"{m['rss_after_warmup_mib']:.0f} MiB"
    )
