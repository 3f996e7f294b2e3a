"""Ctrl-C during a sweep on the local cluster: the terminal sends SIGINT to the whole process
group, so every worker printed its own KeyboardInterrupt traceback (~33 lines each), and an
interrupt while the cluster started left it half made, its ``atexit`` close failing with a
28-line trace. Now the workers are forked from a server that ignores SIGINT, the cluster's
start holds the interrupt back until it is whole, and the command ends with one line and
exit status 130, writing no table. A worker whose heartbeat was in flight as the scheduler
closed logged a 40-line ERROR trace (about one interrupt in twelve mid-sweep); the cluster's
logs are now silenced below CRITICAL."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from radarviz.viz_app.runtime import sigint_deferred

RADARVIZ = [sys.executable, "-m", "radarviz.viz_app.cli.main"]


def test_an_interrupt_in_a_deferred_block_is_raised_when_it_ends() -> None:
    reached_the_end = False
    with pytest.raises(KeyboardInterrupt):
        with sigint_deferred():
            os.kill(os.getpid(), signal.SIGINT)
            reached_the_end = True  # no KeyboardInterrupt inside the block
    assert reached_the_end
    # The block's error is replaced by the interrupt that caused it; without one it stays.
    with pytest.raises(KeyboardInterrupt), sigint_deferred():
        os.kill(os.getpid(), signal.SIGINT)
        raise RuntimeError("Nanny failed to start.")
    with pytest.raises(RuntimeError), sigint_deferred():
        raise RuntimeError("a failure of its own")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def _interrupt_when(tmp_path: Path, marker: str) -> tuple[int, list[str]]:
    """Run a local-cluster sweep in its own process group, send the group SIGINT (as a
    terminal's Ctrl-C does) once a line of standard error matches ``marker``; the exit status
    and every line of standard error."""
    out = tmp_path / "s.parquet"
    argv = [*RADARVIZ, "sweep", "--workers", "2", "--runs", "200000", "--out", str(out)]
    proc = subprocess.Popen(
        argv, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, start_new_session=True
    )
    assert proc.stderr is not None
    lines = []
    for line in proc.stderr:
        lines.append(line.rstrip("\n"))
        if re.search(marker, line):
            os.killpg(proc.pid, signal.SIGINT)
            break
    lines += proc.stderr.read().splitlines()
    code = proc.wait(timeout=120)
    assert not out.exists(), lines
    return code, lines


@pytest.mark.parametrize(
    "marker",
    [r" 0/200000 runs \(0%\)", r" [1-9]\d*/200000 runs"],
    ids=["at the start", "mid-sweep"],
)
def test_ctrl_c_of_a_sweep_is_one_line_and_status_130(tmp_path: Path, marker: str) -> None:
    code, lines = _interrupt_when(tmp_path, marker)
    assert code == 130, lines
    assert lines[-1] == "radarviz: interrupted: sweep stopped, no output written", lines
    assert all(line.startswith("sweep 1 point(s): ") for line in lines[:-1]), lines


def _console_script() -> Path:
    exe = Path(sys.executable).with_name("radarviz")
    if not exe.exists():
        pytest.skip("the radarviz console script is not installed beside this interpreter")
    return exe


@pytest.mark.skipif(not Path("/proc/self/maps").exists(), reason="needs /proc/PID/maps")
@pytest.mark.parametrize("command", [["--help"], ["demo"]])
def test_ctrl_c_during_the_start_up_imports_is_one_line_and_status_130(
    command: list[str],
) -> None:
    """SIGINT once numpy's extension is mapped into the process: the command line's imports
    (numpy, numba, every command's module) are then under way, a second or more of them. It
    used to end in a KeyboardInterrupt traceback from inside some import (4 to 60 lines) and
    the status of a process killed by SIGINT; now the console script's entry module imports
    the command line inside a handler."""
    proc = subprocess.Popen(
        [str(_console_script()), *command],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    maps = Path(f"/proc/{proc.pid}/maps")
    try:
        while proc.poll() is None and "_multiarray_umath" not in maps.read_text():
            pass
    except FileNotFoundError:  # the process ended before numpy was mapped
        pass
    os.killpg(proc.pid, signal.SIGINT)
    assert proc.stderr is not None
    err = proc.stderr.read()
    code = proc.wait(timeout=60)
    assert (code, err.splitlines()) == (
        130,
        ["radarviz: interrupted while starting, nothing done"],
    ), err


class _HalfMadeImport:
    """A finder for the command line's module that behaves as numpy's extension did when
    Ctrl-C came during its initialisation: the interrupt is swallowed inside, and the import
    ends in the ImportError of a second load. ``interrupt``: send the SIGINT first."""

    NAME = "radarviz.viz_app.cli.main"

    def __init__(self, interrupt: bool):
        self.interrupt = interrupt

    def find_spec(self, name: str, path: object = None, target: object = None) -> None:
        if name != self.NAME:
            return None
        if self.interrupt:
            try:
                os.kill(os.getpid(), signal.SIGINT)
                for _ in range(1000):  # the handler runs between two bytecodes
                    pass
            except KeyboardInterrupt:
                pass
        raise ImportError("cannot load module more than once per process")


@pytest.mark.parametrize("interrupt", [True, False], ids=["interrupted", "not interrupted"])
def test_an_import_that_fails_after_ctrl_c_at_start_up_is_the_interrupt(
    monkeypatch, capsys, interrupt: bool
) -> None:
    """After a SIGINT the start-up's failure is the interrupt's: one line, status 130 (it was
    the ImportError's traceback); without one the ImportError is the error, as it was."""
    import radarviz_entry

    monkeypatch.delitem(sys.modules, _HalfMadeImport.NAME, raising=False)
    monkeypatch.setattr(sys, "meta_path", [_HalfMadeImport(interrupt), *sys.meta_path])
    capsys.readouterr()
    if interrupt:
        assert radarviz_entry.main() == radarviz_entry.EXIT_INTERRUPTED
        assert capsys.readouterr().err.splitlines() == [radarviz_entry.STARTUP_INTERRUPTED]
    else:
        with pytest.raises(ImportError, match="more than once"):
            radarviz_entry.main()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
