"""Progress bars (--progress of `clsky table`, `clsky animate`, `clsky bench accuracy`): by default ("auto")
on a terminal only, so that a pipe, a CI log or a cron mail gets the summary lines and not hundreds of
carriage-return updates; forced with leave or display; the orders' bar, whose total is unknown, counts
them as a number ("scattering orders: 6", not tqdm's "6order").
"""

from __future__ import annotations

import fcntl
import io
import os
import pty
import re
import struct
import subprocess
import sys
import termios

import pytest

from clsky import cli


class Terminal(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self):
        return True


def test_auto_shows_no_bar_outside_a_terminal(monkeypatch):
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    update, close = cli.progress_bar("auto")
    assert update is None
    close()
    assert sys.stderr.getvalue() == ""


@pytest.mark.parametrize("mode, stream", [("auto", Terminal), ("leave", io.StringIO)])
def test_bars_on_a_terminal_or_when_asked(monkeypatch, mode, stream):
    monkeypatch.setattr(sys, "stderr", stream())
    update, close = cli.progress_bar(mode)
    for order in (1, 2, 3):
        update("orders", order, None)
    for frame in (1, 2):
        update("frames", frame, 4)
    close()
    lines = sys.stderr.getvalue().replace("\r", "\n").splitlines()
    assert any(re.fullmatch(r"scattering orders: 3 \[\d\d:\d\d\]", line) for line in lines), lines
    frames = [line for line in lines if line.startswith("frames:")]
    assert frames and "2/4" in frames[-1] and "frame/s" in frames[-1]
    assert not any("order/s" in line or "3order" in line for line in lines)


def test_the_accuracy_sweeps_stages_name_their_steps(monkeypatch):
    """`clsky bench accuracy`'s stages (anim/accuracy.py) counted a generic "step": the reference's frames
    and the candidates are named, each with its unit."""
    monkeypatch.setattr(sys, "stderr", io.StringIO())
    update, close = cli.progress_bar("leave")
    update("reference", 0, 4)
    update("reference", 2, 4)
    update("candidates", 0, 3)
    update("candidates", 1, 3)
    update("reference convergence", 0, 4)             # bench_quality's doubled groups (anim/accuracy.py)
    update("reference convergence", 3, 4)
    close()
    lines = sys.stderr.getvalue().replace("\r", "\n").splitlines()
    assert any(line.startswith("reference frames:") and "2/4" in line and "frame/s" in line for line in lines), lines
    assert any(line.startswith("candidates:") and "1/3" in line and "candidate/s" in line for line in lines), lines
    assert any(line.startswith("reference convergence:") and "3/4" in line and "group/s" in line for line in lines)
    assert not any("step" in line for line in lines), lines


def test_command_line_in_a_pipe_prints_only_its_summary(tmp_path):
    result = subprocess.run([sys.executable, "-m", "clsky", "table", "--size", "4", "8", "4", "--orders", "2",
                             "-o", "t.npz"], cwd=tmp_path, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ""
    assert result.stdout.startswith("table 4x8x4 float64")


def test_command_line_on_a_terminal_shows_its_bars(tmp_path):
    """`clsky table` with its standard error on a pseudo-terminal (rows and columns set: tqdm draws
    nothing on a terminal of no rows) shows the single-scattering and orders bars."""
    controller, terminal = pty.openpty()
    fcntl.ioctl(terminal, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 100, 0, 0))
    run = subprocess.Popen([sys.executable, "-m", "clsky", "table", "--size", "4", "8", "4", "--orders", "2",
                            "-o", "t.npz"], cwd=tmp_path, stdout=subprocess.PIPE, stderr=terminal, text=True)
    os.close(terminal)
    shown = b""
    while True:
        try:
            chunk = os.read(controller, 4096)
        except OSError:                         # the child closed the terminal (EIO on Linux)
            break
        if not chunk:
            break
        shown += chunk
    os.close(controller)
    assert run.wait(timeout=60) == 0
    lines = shown.decode().replace("\r", "\n").splitlines()
    assert any(re.fullmatch(r"scattering orders: 2 \[\d\d:\d\d\]", line) for line in lines), lines
    assert any(line.startswith("single scattering:") for line in lines)
