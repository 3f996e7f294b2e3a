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
"""

from __future__ import annotations

import os
import tempfile
import time
import tracemalloc
from typing import Any

#: Plots of the section's file (``radarviz bench --asterix-plots``).
DEFAULT_PLOTS = 20_000


def _read_all(path: str, radars: dict, asterix: bool) -> int:
    from radarviz.viz_app.io.asterix import AsterixReader
    from radarviz.viz_app.io.plots import PlotReader, bounded_lines

    with open(path, "rb") as fh:
        if asterix:
            reader: Any = AsterixReader(fh, path, radars)
        else:
            reader = PlotReader(bounded_lines(fh, path), path, radars)
        return sum(1 for _ in reader)


def bench_asterix(plots: int = DEFAULT_PLOTS, repeats: int = 3) -> dict[str, Any]:
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
    }


def format_asterix(doc: dict[str, Any]) -> str:
    """The section's lines of the report."""
    bpp = doc["bytes_per_plot"]
    return (
        f"ASTERIX CAT048 reading, {doc['plots']} fusion plots (3D, Doppler), best of "
        f"{doc['repeats']}: {doc['asterix_plots_per_s']:.0f} plots/s (decoder alone "
        f"{doc['decoder_plots_per_s']:.0f}); CSV of the same plots {doc['csv_plots_per_s']:.0f} "
        f"plots/s (ASTERIX/CSV {doc['asterix_over_csv']:.2f}×); {bpp['asterix']:.1f} vs "
        f"{bpp['csv']:.1f} bytes per plot; peak allocation while reading "
        f"{doc['read_peak_kib']:.0f} KiB for a {doc['file_kib']:.0f} KiB file (reads of "
        f"{doc['read_bytes_kib']:.0f} KiB)"
    )
