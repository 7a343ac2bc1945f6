"""Progress: the generated programs' `--progress` lines (stderr only, the CSV the same bytes),
and `bgc simulate`'s bar on a terminal (a pseudo-terminal here), silent elsewhere."""
import io
import os
import pty
import re
import select
import subprocess
import sys

import pytest

import bgc
from bgc.base import cache, processes
from bgc import cli
from bgc.codegen.emit import emit_c, emit_python
from conftest import MODELS, have_cc, run_bgc

PENDULUM = MODELS / "pendulum.bg"
LINE = re.compile(r"bgc-progress (\S+) (\S+) (\S+)")


@pytest.fixture(scope="module")
def program():
    return bgc.build(PENDULUM, "swing").program


def _progress_lines(stderr: str):
    return [tuple(map(float, m.groups())) for m in map(LINE.fullmatch, stderr.splitlines())
            if m]


@pytest.mark.skipif(not have_cc(), reason="no C compiler")
def test_c_program_progress_on_stderr_only(program):
    (text,) = emit_c(program).values()
    exe = cache.compile_c(text)
    args = ["--t-end", "2"]
    plain = subprocess.run([exe, *args], capture_output=True)
    told = subprocess.run([exe, *args, "--progress"], capture_output=True)
    assert plain.returncode == told.returncode == 0
    assert told.stdout == plain.stdout and plain.stderr == b""
    lines = _progress_lines(told.stderr.decode())
    assert lines[0] == (0.0, 0.0, 2.0)  # the first row always; then at most 10 a second
    assert len(lines) == len(told.stderr.decode().splitlines())
    assert "--progress" in subprocess.run([exe, "--help"], capture_output=True, text=True).stdout


def test_python_module_progress_on_stderr_only(program, capsys):
    (text,) = emit_python(program).values()
    module = processes.load_python_module(text)
    assert module.main(["--t-end", "2"]) == 0
    plain = capsys.readouterr()
    assert module.main(["--t-end", "2", "--progress"]) == 0
    told = capsys.readouterr()
    assert told.out == plain.out and plain.err == ""
    lines = _progress_lines(told.err)
    assert lines[0] == (0.0, 0.0, 2.0) and len(lines) == len(told.err.splitlines())


class _Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_renderer_waits_a_second_then_draws_t_percent_and_eta(monkeypatch):
    err = io.StringIO()
    err.isatty = lambda: True
    monkeypatch.setattr(sys, "stderr", err)
    clock = _Clock()
    bar = cli._RunProgress(clock=clock)
    bar(1.0, 0.0, 10.0)
    clock.now += 0.9
    bar(2.0, 0.0, 10.0)
    assert err.getvalue() == ""  # under a second: nothing
    clock.now += 1.1  # 2 s for the first quarter: 6 s to go
    bar(2.5, 0.0, 10.0)
    assert err.getvalue() == \
        "\r\033[K[#######.......................] 2.5/10 t, 25%, 2.0 s, ETA 6.0 s"
    bar.close()
    assert err.getvalue().endswith("\r\033[K")


def test_simulate_draws_the_bar_on_a_terminal_only(tmp_path, monkeypatch):
    """The same run with stderr a pseudo-terminal (the bar, drawn from the first progress line
    once PROGRESS_AFTER is 0) and not (no bar, no progress line): the same CSV."""
    master, slave = pty.openpty()
    try:
        with open(slave, "w", closefd=False) as tty:
            monkeypatch.setattr(sys, "stderr", tty)
            monkeypatch.setattr(cli, "PROGRESS_AFTER", 0.0)
            args = ["simulate", str(PENDULUM), "--scene", "swing", "--t-end", "2",
                    "--backend", "c" if have_cc() else "python"]
            with pytest.raises(SystemExit) as done:
                cli.main([*args, "-o", str(tmp_path / "tty.csv")])
            assert done.value.code == 0
            tty.flush()
            monkeypatch.undo()  # (sys.stderr back before its file closes)
        shown = b""
        while select.select([master], [], [], 0.5)[0]:  # (the pty hands data on asynchronously)
            chunk = os.read(master, 1 << 16)
            if not chunk:
                break
            shown += chunk
        shown = shown.decode()
    finally:
        os.close(master)
        os.close(slave)
    assert "\r\033[K[" in shown and "/2 t, " in shown and "ETA" in shown
    assert shown.endswith("\r\033[K") and "bgc-progress" not in shown
    quiet = run_bgc(*args, "-o", tmp_path / "pipe.csv")
    assert quiet.returncode == 0 and quiet.stderr == ""
    assert (tmp_path / "tty.csv").read_bytes() == (tmp_path / "pipe.csv").read_bytes()
