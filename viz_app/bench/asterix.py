"""``radarviz bench``, section ``asterix``: reading ASTERIX CAT048 against reading CSV.

The fusion preset's plots (three 3D radars with Doppler, ``plots`` in all) are written once as
an ASTERIX file (``viz_app.io.asterix.write_asterix``) and as a measurement CSV
(``write_measurements``), not timed. Then, interleaved in one process, best of ``repeats``:

* ``asterix_plots_per_s``: ``AsterixReader`` over the file, plots made and validated (the
  decoder, pyobelix, and the conversion to plots);
* ``decoder_plots_per_s``: pyobelix alone on the same bytes (records decoded, nothing else);
* ``csv_plots_per_s``: ``PlotReader`` over the CSV (the same plots, the same checks);
* ``asterix_over_csv``: the ratio of the first and the third, same run.

``bytes_per_plot`` gives both files' sizes. ``read_peak_kib``: the peak of Python's allocations
(tracemalloc) during one more pass of the ASTERIX reader that keeps no plot, with the file's
size beside it: reading holds one read of ``READ_BYTES`` and one data block, whatever the
file's length.

``track``: ``radarviz track`` end to end on an ASTERIX file of the air-traffic scene
(``viz_app.bench.track_file.air_traffic_file``: ``targets`` aircraft, two 3D radars with
Doppler, ``plots`` plots; written once, not timed), all 3D methods, the cv model with
σa = 1 m/s² (``CV_TRACK``'s), the track CSV written. Interleaved in one process, best of
``repeats`` each, wall and CPU time (``time.process_time``: every thread's, so the track
file's formatting threads count):

* ``block``: ``viz_app.io.plot_blocks.run_track``, the command's route: the reader's
  ``PlotBlock`` s tracked on the compiled engine;
* ``row``: ``viz_app.io.plots.run_track``, the row path (a ``Plot`` at a time), which the
  command took for ASTERIX before and still takes for a recording or the association;
* ``decoder``: pyobelix alone on the file's bytes, the floor of both;
* ``csv``: the same plots from the scene's CSV (full precision, not the items' rounding)
  through the block path, the tracking and writing without ASTERIX;
* ``block_over_row`` (the same-run speed-up), ``block_over_decoder`` (the end-to-end rate
  over decoding alone: 1 would be a route limited by the decoder alone) and
  ``block_over_csv``, wall time.
"""

from __future__ import annotations

import math
import os
import tempfile
import time
import tracemalloc
from typing import Any

#: Plots of the section's files (``radarviz bench --asterix-plots``).
DEFAULT_PLOTS = 20_000
#: Targets of the ``track`` figure's file (``radarviz bench --asterix-targets``).
DEFAULT_TARGETS = 200
#: The ``track`` figure's options: ``viz_app.bench.engine.CV_TRACK``'s (cv, σa = 1 m/s²).
TRACK_SIGMA_A_MPS2 = 1.0


def _read_all(path: str, radars: dict, asterix: bool) -> int:
    from radarviz.viz_app.io.asterix import AsterixReader
    from radarviz.viz_app.io.plots import PlotReader, bounded_lines

    with open(path, "rb") as fh:
        if asterix:
            reader: Any = AsterixReader(fh, path, radars)
        else:
            reader = PlotReader(bounded_lines(fh, path), path, radars)
        return sum(1 for _ in reader)


def bench_asterix(
    plots: int = DEFAULT_PLOTS, repeats: int = 3, targets: int = DEFAULT_TARGETS
) -> dict[str, Any]:
    """The ``asterix`` figures (module docstring)."""
    import pyobelix

    from radarviz.viz_app.io.asterix import READ_BYTES, write_asterix
    from radarviz.viz_app.io.plots import load_radars, simulated_plots, write_measurements

    sim, radar_list = simulated_plots("fusion", 1, 1.0, -(-plots // 3))
    sim = sim[:plots]
    with tempfile.TemporaryDirectory(prefix="radarviz-bench-") as tmp:
        ast, csv_path = os.path.join(tmp, "m.ast"), os.path.join(tmp, "m.csv")
        toml, csv_toml = os.path.join(tmp, "r.toml"), os.path.join(tmp, "r_csv.toml")
        write_asterix(ast, toml, sim, radar_list)
        write_measurements(csv_path, csv_toml, sim, radar_list)
        radars = load_radars(toml)
        with open(ast, "rb") as fh:
            data = fh.read()
        best = {"asterix": float("inf"), "decoder": float("inf"), "csv": float("inf")}
        for _ in range(repeats):
            for what in best:
                t0 = time.perf_counter()
                if what == "decoder":
                    n = sum(1 for _ in pyobelix.iter_records(data))
                else:
                    n = _read_all(ast if what == "asterix" else csv_path, radars, what == "asterix")
                best[what] = min(best[what], time.perf_counter() - t0)
                assert n == len(sim), (what, n)
        tracemalloc.start()
        _read_all(ast, radars, True)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        sizes = {"asterix": os.path.getsize(ast), "csv": os.path.getsize(csv_path)}
    rate = {k: len(sim) / v for k, v in best.items()}
    track = bench_asterix_track(plots, repeats, targets)
    return {
        "plots": len(sim),
        "repeats": repeats,
        "asterix_plots_per_s": rate["asterix"],
        "decoder_plots_per_s": rate["decoder"],
        "csv_plots_per_s": rate["csv"],
        "asterix_over_csv": rate["asterix"] / rate["csv"],
        "bytes_per_plot": {k: v / len(sim) for k, v in sizes.items()},
        "file_kib": sizes["asterix"] / 1024,
        "read_bytes_kib": READ_BYTES / 1024,
        "read_peak_kib": peak / 1024,
        "track": track,
    }


def bench_asterix_track(plots: int, repeats: int, targets: int) -> dict[str, Any]:
    """The ``track`` figures (module docstring)."""
    from pathlib import Path

    import pyobelix

    from radarviz.core.tracking.stream import StreamOptions
    from radarviz.viz_app.bench.track_file import air_traffic_file
    from radarviz.viz_app.io import plot_blocks
    from radarviz.viz_app.io import plots as plots_io
    from radarviz.viz_app.io.asterix import asterix_source, write_asterix

    options = StreamOptions(sigma_a_mps2=TRACK_SIGMA_A_MPS2, model="cv")
    with tempfile.TemporaryDirectory(prefix="radarviz-bench-") as tmp:
        d = Path(tmp)
        csv_path, ast, toml = d / "m.csv", str(d / "m.ast"), str(d / "r.toml")
        air_traffic_file(csv_path, d / "r_csv.toml", targets, plots, three_d=True)
        radars = plots_io.load_radars(str(d / "r_csv.toml"))
        with open(csv_path, "rb") as fh:
            lines = plots_io.bounded_lines(fh, str(csv_path))
            sim = [p for _, p in plots_io.PlotReader(lines, str(csv_path), radars)]
        write_asterix(ast, toml, sim, list(radars.values()))
        n = len(sim)
        del sim  # not held while timing (the collector would walk its objects)
        data = Path(ast).read_bytes()
        routes = {"block": plot_blocks.run_track, "row": plots_io.run_track}
        best = {k: (math.inf, math.inf) for k in ("decoder", *routes, "csv")}
        outputs = {}
        for _ in range(repeats):
            for what in best:
                out = str(d / f"{what}.csv")
                wall, cpu = time.perf_counter(), time.process_time()
                if what == "decoder":
                    got = sum(1 for _ in pyobelix.iter_records(data))
                elif what == "csv":
                    csv_toml = str(d / "r_csv.toml")
                    got = plot_blocks.run_track(str(csv_path), csv_toml, out, None, options).plots
                else:
                    run = routes[what](ast, toml, out, None, options, open_source=asterix_source)
                    got = run.plots
                wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
                best[what] = (min(best[what][0], wall), min(best[what][1], cpu))
                assert got == n, (what, got)
                if what in routes:
                    outputs[what] = os.path.getsize(out)
        # The routes' track files, the same bytes (``tests/test_asterix.py``): the same size.
        assert outputs["block"] == outputs["row"], outputs
    figures: dict[str, Any] = {"plots": n, "targets": targets, "repeats": repeats}
    for what, (wall, cpu) in best.items():
        figures[what] = {"plots_per_s": n / wall, "plots_per_cpu_s": n / cpu}
    figures["block_over_row"] = best["row"][0] / best["block"][0]
    figures["block_over_decoder"] = best["decoder"][0] / best["block"][0]
    figures["block_over_csv"] = best["csv"][0] / best["block"][0]
    return figures


def format_asterix(doc: dict[str, Any]) -> str:
    """The section's lines of the report."""
    bpp = doc["bytes_per_plot"]
    t = doc["track"]
    track = (
        f"\nASTERIX track end to end, {t['plots']} plots of {t['targets']} targets (two 3D "
        f"radars, Doppler; all 3D methods, cv), best of {t['repeats']}: compiled block path "
        f"{t['block']['plots_per_s']:.0f} plots/s ({t['block']['plots_per_cpu_s']:.0f} per "
        f"CPU-s), row path {t['row']['plots_per_s']:.0f} plots/s "
        f"({t['row']['plots_per_cpu_s']:.0f} per CPU-s): block/row {t['block_over_row']:.2f}×; "
        f"decoder alone {t['decoder']['plots_per_s']:.0f} plots/s, block/decoder "
        f"{t['block_over_decoder']:.2f}×; the CSV of the plots {t['csv']['plots_per_s']:.0f} "
        f"plots/s, block/CSV {t['block_over_csv']:.2f}× (same run)"
    )
    return (
        f"ASTERIX CAT048 reading, {doc['plots']} fusion plots (3D, Doppler), best of "
        f"{doc['repeats']}: {doc['asterix_plots_per_s']:.0f} plots/s (decoder alone "
        f"{doc['decoder_plots_per_s']:.0f}); CSV of the same plots {doc['csv_plots_per_s']:.0f} "
        f"plots/s (ASTERIX/CSV {doc['asterix_over_csv']:.2f}×); {bpp['asterix']:.1f} vs "
        f"{bpp['csv']:.1f} bytes per plot; peak allocation while reading "
        f"{doc['read_peak_kib']:.0f} KiB for a {doc['file_kib']:.0f} KiB file (reads of "
        f"{doc['read_bytes_kib']:.0f} KiB)" + track
    )
