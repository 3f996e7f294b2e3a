"""``viz_app.io.arrow_numpy`` against pyarrow's own conversions, and the track command
without pandas."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
import pytest

from radarviz.viz_app.bench.track_file import air_traffic_file
from radarviz.viz_app.io.arrow_numpy import from_numpy, strings, to_numpy


@pytest.mark.parametrize("dtype", [np.float64, np.int32, np.int64])
def test_to_numpy_is_pyarrows_conversion_with_nulls_offsets_and_chunks(dtype) -> None:
    rng = np.random.default_rng(4)
    values = (rng.normal(0, 1e3, 1000)).astype(dtype)
    mask = rng.random(1000) < 0.2
    arr = pa.array(values, mask=mask)
    chunked = pa.chunked_array([arr[:300], arr[300:]])
    for a in (arr, arr.slice(37, 500), chunked, pa.array(values), arr.slice(999)):
        ours = to_numpy(a)
        theirs = a.to_numpy(zero_copy_only=False)
        assert ours.dtype == dtype and ours.flags.writeable
        if np.issubdtype(dtype, np.floating):
            np.testing.assert_array_equal(ours, theirs)  # NaN where null, on both
        else:
            nulls = np.asarray(a.is_null().to_pylist(), dtype=bool)
            np.testing.assert_array_equal(ours[~nulls], np.asarray(theirs)[~nulls])
            assert (ours[nulls] == 0).all()


def test_from_numpy_and_strings_are_pa_array() -> None:
    x = np.random.default_rng(5).normal(size=257)
    assert from_numpy(x).equals(pa.array(x))
    assert from_numpy(np.arange(9, dtype=np.int32)[::2]).equals(
        pa.array(np.arange(0, 9, 2, np.int32))
    )
    texts = ["north", "", "süd", 'a "quoted" one']
    assert strings(texts).equals(pa.array(texts, pa.string()))
    table = pcsv.read_csv(io.BytesIO("r\nsüd\nnorth\nx\n".encode()))
    idx = pc.index_in(table.column("r"), value_set=strings(texts))
    assert idx.to_pylist() == [2, 0, None]


@pytest.mark.parametrize("out", ["tracks.csv", "tracks.parquet"])
def test_the_track_command_does_not_import_pandas(tmp_path: Path, out: str) -> None:
    """pyarrow's conversions would import pandas (30 MB of the command's peak memory)."""
    meas, radars = tmp_path / "plots.csv", tmp_path / "radars.toml"
    air_traffic_file(meas, radars, targets=20, plots=400, three_d=True)
    code = (
        "import sys\n"
        "from radarviz.viz_app.cli.main import main\n"
        "rc = main(sys.argv[1:])\n"
        "print('pandas' in sys.modules, rc)\n"
    )
    cmd = [sys.executable, "-c", code, "track", "--input", str(meas), "--radars", str(radars)]
    cmd += ["--out", str(tmp_path / out), "--model", "cv"]
    done = subprocess.run(cmd, capture_output=True, text=True, check=True)
    assert done.stdout.split()[-2:] == ["False", "0"], done.stderr
