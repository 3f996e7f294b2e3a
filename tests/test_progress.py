"""The progress bar writes to its stream only, every 10% when not on a terminal."""

from __future__ import annotations

import io

from radarviz.viz_app.cli.progress import ProgressBar


def test_progress_bar_prints_deciles_off_terminal() -> None:
    stream = io.StringIO()
    bar = ProgressBar("prosov", stream=stream)
    for done in range(0, 1001, 50):
        bar(done, 1000)
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("prosov: 0/1000 runs (0%)")
    assert lines[-1].startswith("prosov: 1000/1000 runs (100%)")
    assert len(lines) == 11  # 0%, 10%, …, 100%
