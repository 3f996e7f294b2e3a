"""``sweep`` outputs checked before computing: a ``--plot`` directory that cannot be made, a
figure name taken by a directory, and a chunks directory name taken by a file were each found
only after every chunk was computed (or as the chunks began), with a bare OS message. Each is
now one line naming the flag, exit status 2, before any chunk runs, and nothing is left."""

from __future__ import annotations

from pathlib import Path

import pytest

import radarviz.viz_app.cli.sweep as sweep_cli
from radarviz.viz_app.cli.main import main

ARGV = ["sweep", "--scheduler", "serial", "--runs", "3", "--steps", "5", "--json"]


def _no_computing(*args: object, **kwargs: object) -> None:
    raise AssertionError("the sweep was computed before its outputs were checked")


@pytest.mark.parametrize("case", ["plot under a file", "figure is a directory", "chunks file"])
def test_sweep_outputs_are_refused_before_computing(
    tmp_path: Path, capsys, monkeypatch, case: str
) -> None:
    monkeypatch.setattr(sweep_cli, "run_sweep", _no_computing)
    out = tmp_path / "s.parquet"
    argv = [*ARGV, "--out", str(out), "--grid", "sigma_beta_deg=1,2"]
    (tmp_path / "a_file").write_text("kept")
    if case == "plot under a file":
        plot = tmp_path / "a_file" / "figures"
        argv += ["--plot", str(plot)]
        expected = f"radarviz: error: --plot: cannot create the directory {str(plot)!r} ("
    elif case == "figure is a directory":
        plot = tmp_path / "new" / "figures"
        (plot / "sweep_nees_pos.png").mkdir(parents=True)
        argv += ["--plot", str(plot)]
        expected = f"radarviz: error: --plot must name a regular file ({plot}/sweep_nees_pos.png"
    else:
        Path(f"{out}.chunks").write_text("kept")
        expected = f"radarviz: error: --out: its chunks directory '{out}.chunks' exists and is"
    assert main(argv) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.strip().splitlines()
    assert line.startswith(expected), line
    assert captured.out == "" and not out.exists()
    assert (tmp_path / "a_file").read_text() == "kept"


def test_a_plot_directory_made_for_a_sweep_that_fails_is_removed(
    tmp_path: Path, capsys, monkeypatch
) -> None:
    """The directory ``--plot`` asks for is made before computing (so a path that cannot be
    one fails first); a sweep that then fails leaves no empty directories behind."""

    def aborted(*args: object, **kwargs: object) -> None:
        raise sweep_cli.SweepAbortedError("a chunk failed")

    monkeypatch.setattr(sweep_cli, "run_sweep", aborted)
    plot = tmp_path / "new" / "figures"
    assert main([*ARGV, "--out", str(tmp_path / "s.parquet"), "--plot", str(plot)]) == 1
    assert capsys.readouterr().err.strip() == "radarviz: error: a chunk failed"
    assert not (tmp_path / "new").exists()
