"""``radarviz bench``'s air-traffic file: many targets, many plots, tracked end to end.

``air_traffic_file`` writes a measurement file of ``targets`` aircraft flying straight at
constant speed (random start, heading and speed 100–300 m/s, within 20–180 km of the first
radar), seen by two radars with staggered scans of period 5 s: each scan of each radar gives
one plot of every target, with noise σr, σβ (σε in 3D) and, in 3D, a radial velocity (σVr);
a 2D file is the same scene in the x–y plane. Plots are in time order, targets interleaved,
written with pyarrow's CSV writer a scan at a time.

``time_track`` runs ``radarviz track`` on it in a fresh process (so the peak memory and the
CPU time are the command's own) and returns them with the wall time.
"""

from __future__ import annotations

import math
import subprocess
import sys
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np

PERIOD_S = 5.0
#: The radars: sites (m) and noise (σr m, σβ deg, σε deg, σVr m/s).
RADARS = (
    ("north", (0.0, 0.0, 0.0), (120.0, 0.15, 0.2, 1.0)),
    ("south", (60_000.0, -40_000.0, 30.0), (200.0, 0.25, 0.3, 1.5)),
)


def air_traffic_file(
    path: Path, radars_path: Path, targets: int, plots: int, three_d: bool, seed: int = 5
) -> int:
    """Write the file (module docstring) of about ``plots`` plots; returns the plots written."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    rng = np.random.default_rng(seed)
    rho = rng.uniform(20e3, 180e3, targets)
    ang = rng.uniform(-math.pi, math.pi, targets)
    p0 = np.stack([rho * np.cos(ang), rho * np.sin(ang), rng.uniform(1e3, 11e3, targets)], 1)
    head = rng.uniform(-math.pi, math.pi, targets)
    speed = rng.uniform(100.0, 300.0, targets)
    v = np.stack([speed * np.cos(head), speed * np.sin(head), np.zeros(targets)], 1)
    n_radars = len(RADARS)
    scans = max(1, math.ceil(plots / (targets * n_radars)))
    labels = pa.array([f"AC{k:05d}" for k in range(targets)])
    writer = None
    written = 0
    with open(path, "wb") as fh:
        for n in range(scans):
            for g, (
                name,
                site,
                (sigma_r_m, sigma_beta_deg, sigma_elevation_deg, sigma_vr_mps),
            ) in enumerate(RADARS):
                # Targets swept in azimuth order within a scan: 1 ms apart.
                t = n * PERIOD_S + g * PERIOD_S / n_radars + 1e-3 * np.arange(targets)
                pos = p0 + v * t[:, None] - np.asarray(site)
                if not three_d:  # a 2D file: the plane of the radars
                    pos[:, 2] = 0.0
                r = np.linalg.norm(pos, axis=1)
                cols = {
                    "time_s": t,
                    "radar": pa.array([name] * targets),
                    "range_m": r + rng.normal(0, sigma_r_m, targets),
                    "azimuth_deg": np.degrees(
                        np.arctan2(pos[:, 1], pos[:, 0])
                        + rng.normal(0, math.radians(sigma_beta_deg), targets)
                    ),
                }
                if three_d:
                    el = np.arcsin(pos[:, 2] / r) + rng.normal(
                        0, math.radians(sigma_elevation_deg), targets
                    )
                    cols["elevation_deg"] = np.degrees(el)
                    vr = np.einsum("ij,ij->i", pos, v) / r + rng.normal(0, sigma_vr_mps, targets)
                    cols["radial_velocity_mps"] = vr
                cols["target"] = labels
                table = pa.table(cols)
                if writer is None:
                    writer = pcsv.CSVWriter(
                        fh, table.schema, write_options=pcsv.WriteOptions(quoting_style="none")
                    )
                writer.write_table(table)
                written += targets
        if writer is not None:
            writer.close()
    toml = []
    for name, site, (sigma_r_m, sigma_beta_deg, sigma_elevation_deg, sigma_vr_mps) in RADARS:
        toml += [
            f"[radars.{name}]",
            f"x_m = {site[0]!r}",
            f"y_m = {site[1]!r}",
            f"z_m = {site[2]!r}",
            f"sigma_r_m = {sigma_r_m!r}",
            f"sigma_beta_deg = {sigma_beta_deg!r}",
            f"sigma_elevation_deg = {sigma_elevation_deg!r}",
            f"sigma_vr_mps = {sigma_vr_mps!r}",
            "",
        ]
    radars_path.write_text("\n".join(toml))
    return written


class TrackRun(NamedTuple):
    """One ``radarviz track`` run: wall time and CPU time (user + system) in s, peak resident
    memory in MB."""

    wall_s: float
    cpu_s: float
    peak_rss_mb: float


def time_track(meas: Path, radars: Path, out: Path, extra: tuple[str, ...] = ()) -> TrackRun:
    """``radarviz track`` on the file in a fresh process (so the memory and CPU time are the
    command's own; numba's cached kernels are loaded, not compiled: a first run compiles)."""
    code = (
        "import resource, sys\n"
        "from radarviz.viz_app.cli.main import main\n"
        "rc = main(sys.argv[1:])\n"
        "u = resource.getrusage(resource.RUSAGE_SELF)\n"
        # VmHWM is this program's own peak; ru_maxrss would keep the forking parent's.
        "hwm = [ln.split()[1] for ln in open('/proc/self/status') if ln.startswith('VmHWM')]\n"
        "print(u.ru_utime + u.ru_stime, (hwm or [u.ru_maxrss])[0], file=sys.stderr)\n"
        "sys.exit(rc)\n"
    )
    cmd = [sys.executable, "-c", code, "track"]
    cmd += ["--input", str(meas), "--radars", str(radars), "--out", str(out), *extra]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t0
    cpu, peak_kb = done.stderr.decode().strip().splitlines()[-1].split()
    return TrackRun(wall, float(cpu), int(peak_kb) / 1024.0)
