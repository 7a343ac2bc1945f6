#!/usr/bin/env python3
"""Fuzzing bgc's command line: the options and option values of every command.

    python tools/fuzz_options.py --seed 1 --cases 5000 --out fuzz-options-out

Each case is a valid command line of one command (check, scenes, equations, compile, draw,
simulate, sweep, accuracy, linearize, steady, fit: every command click knows, with every
option it takes) on a small model, changed one to four times: an option set to a value of its
kind taken to extremes (numbers: 0, -1, 1e308, 1e309, 1e-400, nan, inf, 1_0, Arabic-Indic and
full-width digits, 400 digits, empty; names: unknown, unicode, empty, with spaces or commas;
paths: a directory, a missing directory, a character device, a FIFO, a symbolic link to the
model, the model itself, a name too long, `-`), an option repeated, an unknown option, a token
removed, `--opt=VALUE` for `--opt VALUE`; an output aimed at a file the command reads (the
model lm.bg, which imports a library and reads a table, with an --input, a --data or a
--reference CSV: the file itself, a symbolic or a hard link to it, a directory output whose
file is a hard link to it); one output option or two given `-`.  It runs in a directory of
its own that holds the models, those files and paths (the devices are private copies of
/dev/null and /dev/full, made with mknod when the harness may; never the system's).

What counts as a failure:
- an exception other than the command's exit (a traceback), or "Traceback" in the output;
- an exit status other than 0, 1 and 2 (docs/cli.md, "Exit statuses"), or 1 or 2 without a
  message on stderr;
- a half-written output: a hidden file left in the directory (a temporary, a `.part`), a file
  that the command was not asked to write, any new file after a usage error (exit 2), a CSV
  whose last row is cut;
- a file the command reads (its model, a library and a table it reads, its --input, --data,
  --reference) changed, or a name of it (a symbolic or a hard link) replaced; a file named
  `-` (standard output was meant); exit 0 with nothing on stdout for an output given `-`;
- a path of the directory changed in kind: the FIFO, the devices, a symbolic link or a
  directory replaced by something else;
- a case that runs longer than --time-limit (a hang: its worker is killed and the run goes on).

Cases run in process (the function the command line calls, through click's runner) in a
worker process, which is restarted after a hang or a crash.  The summary (cases, exit
statuses by command, failures with the first command line of each) is printed and written to
OUT/summary.json; the failing command lines to OUT/failures.txt.  tests/test_fuzz_options.py
runs a short seeded campaign in process (options(rng, quick=True), run_case).
"""
from __future__ import annotations

import argparse
import json
import os
import random
import select
import signal
import stat
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

MODEL = """model m "a source, a resistor and a capacitor"
parameter R = 2.0 "resistance"
parameter C = 0.5 "capacitance"
parameter V = 1.0 "supply"
u : MSe(V)
j : 1
n : 0
r : R(R) @loss
c : C(C) init q = 0
u -> j
j -> r
j -> n
n -> c
scene run "one second" { outputs c.q, r.f; time 0 .. 1 every 0.1 }
scene other { effects none; outputs c.q; time 0 .. 0.5 every 0.25; solver rk4(step = 0.01) }
"""

# m's circuit reading files: a library it imports, a table, an input (its outputs as m's)
READING = """model lm "m's circuit: its supply a table and an input, its resistor a library's"
import parts
input u = 0 "a voltage added to the supply"
parameter R = 2.0 "resistance"
parameter C = 0.5 "capacitance"
parameter V = 1.0 "supply"
signal v = V * table(curve.csv, t)
src : MSe(v + u)
j : 1
n : 0
r : parts.resistor(r = R) @loss
c : C(C) init q = 0
src -> j
j -> r.p
j -> n
n -> c
scene run "one second" { outputs c.q, r.x.f; time 0 .. 1 every 0.1 }
scene other { effects none; outputs c.q; time 0 .. 0.5 every 0.25; solver rk4(step = 0.01) }
"""
PARTS = """library parts "the fuzzer's library"
component resistor(r = 1) "a resistor at port p" {
  port p
  x : R(r)
  p -> x
}
"""
MEASURED = "t,c.q\n" + "".join(f"{k / 10:g},{0.4 * (1 - 0.9 ** k):.6f}\n" for k in range(11))
FILES = {"parts.bg": PARTS, "curve.csv": "t,v\n0,1\n0.5,1\n1,0.5\n",
         "inp.csv": "t,u\n0,0\n1,0.5\n", "data.csv": MEASURED, "ref.csv": MEASURED}
# names of those files: symbolic and hard links, and links inside the directories that
# accuracy's -o and sweep's --trajectories name (accdir/accuracy.csv, trajdir/run-000000.csv)
SYMLINKS = {"parts-link.bg": "parts.bg", "curve-link.csv": "curve.csv",
            "inp-link.csv": "inp.csv", "lib.dot": "parts.bg", "ref-link.json": "ref.csv"}
HARDLINKS = {"parts-hard.bg": "parts.bg", "curve-hard.csv": "curve.csv",
             "data-hard.json": "data.csv", "inp-hard.csv": "inp.csv",
             "accdir/accuracy.csv": "ref.csv", "trajdir/run-000000.csv": "curve.csv"}
AT_INPUTS = ("lm.bg", "parts.bg", "curve.csv", "inp.csv", "data.csv", "ref.csv",
             *SYMLINKS, *(h for h in HARDLINKS if "/" not in h))
INPUT_PATHS = ("inp.csv", "inp-link.csv", "inp-hard.csv", "data.csv", "data-hard.json",
               "ref.csv", "curve.csv", "m.bg", "missing.csv", "adir", "nulldev", "")

# valid command lines, one per command (the model is m.bg in the working directory)
BASE = {
    "check": ["check", "m.bg"],
    "scenes": ["scenes", "m.bg"],
    "equations": ["equations", "m.bg", "-s", "run"],
    "compile": ["compile", "m.bg", "-s", "run", "-o", "out.c"],
    "draw": ["draw", "m.bg", "-o", "out.dot"],
    "simulate": ["simulate", "m.bg", "-s", "run", "-o", "out.csv"],
    "sweep": ["sweep", "m.bg", "-s", "run", "--grid", "R=1,2", "--metric", "final:c.q",
              "--workers", "0", "-o", "table.csv"],
    "accuracy": ["accuracy", "m.bg", "-s", "other", "--solvers", "rk4,dopri5", "--rtols",
                 "1e-3", "--steps", "0.05", "--repeats", "1", "--no-plot", "-o", "acc"],
    "linearize": ["linearize", "m.bg", "-s", "run", "--at", "t=0.5", "-o", "lin.json"],
    "steady": ["steady", "m.bg", "-s", "run", "--json", "rest.json"],
    "fit": ["fit", "m.bg", "-s", "run", "--data", "data.csv", "--vary", "R", "--backend",
            "python", "-o", "fit.json"],
}
SLOW = {"accuracy", "fit"}  # left out of the quick (suite) campaign

NUMBERS = ("0", "-0", "1", "-1", "2", "0.5", "1e-3", "1e-300", "1e300", "1e308", "1e309",
           "1e-400", "4.9e-324", "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1_0",
           "\u0663", "\uff11", "\u00b9", "", " ", "1e", "0x10", "1,5", "9" * 400,
           "1" + "0" * 30, "2**10", "+1", ".5", "5.", "1e-12", "4096", "4097", "-4097",
           "10000001", "1\u200b", "１e３")
NAMES = ("", " ", "nope", "R", "C", "V", "c.q", "r.f", "t", "m", "run", "é", "\u202e",
         "R.x", "c.lamda", "q[0]", "c.q,", ",", "c.q, r.f", "c.q,c.q", "a" * 300,
         "R=1", "--", "-", "run ", "\u0280un", "ｒun", "x\ny", "default")
# paths inside the case's directory (see _setup); never one outside it
PATHS = ("out.csv", "out.c", "out.py", "out.fmu", "out.svg", "out.png", "out.dot",
         "out.json", "out.tex", "out.parquet", "adir", "adir/", ".", "", "missing/out.csv",
         "m.bg", "./m.bg", "adir/../m.bg", "link", "fifo", "nulldev", "fulldev",
         "out.csv/x", "-", "\U0001f4a5.csv", "a" * 300 + ".csv", "target-link.csv",
         "a b.csv", "--help", "./-", "parts.bg", "curve-hard.csv", "inp-link.csv")
CHOICE_JUNK = ("", "nope", "C", "ｃ", "c ", "python3", "-", "auto")
STRING_VALUES = {  # options whose value is a small language of its own
    "-p": ["R=3", "C=1e-3", "V=0", "nope=1", "R", "=1", "R==1", "R=", "R= 1",
           "c.q=1", "R=1=2", "R=1,2"],
    "--const": ["N=3", "N=-1", "N=1e400", "nope=1", "N", "N=1.5", "="],
    "--scene": ["run", "other", "nope", "", "run,other", "ｒun", "default"],
    "-s": ["run", "other", "nope", "", "run,other"],
    "--outputs": ["c.q", "c.q, r.f", "nope", "c.q,", "", "t", "c.lamda", "c.q,c.q", "r"],
    "--effects": ["loss", "none", "nope", "", "loss,loss", "loss,none"],
    "--grid": ["R=1:2:lin3", "R=1,2", "R=1:2:log0", "R=0:1:log3", "R=-1:1:log2",
               "R=1:2:lin100000000", "nope=1,2", "R=", "R=nan,1", "R=1:2:lin3x", "=1",
               "R=1:2:lin0", "R=1e400,1", "C=1,2", "R=1;2"],
    "--vary": ["R=uniform(1,2)", "R=normal(1,-1)", "R=loguniform(0,1)", "R=uniform(2,1)",
               "R=foo(1,2)", "R=uniform(1e400,2)", "R=normal(nan,1)", "R=uniform(1,2",
               "nope=uniform(1,2)", "R=uniform(,)"],
    "--metric": ["final:c.q", "max:r.f", "nope:c.q", "final:nope", "final", ":c.q",
                 "rms:t", "final:c.q:x", "min:c.q"],
    "--at": ["t=0", "t=0.5", "steady", "t=nan", "t=-1", "t=1e400", "nope", "t=", "t=2"],
    "--inputs": ["V", "nope", "", "V,V", "R", "u"],
    "--solvers": ["rk4,dopri5", "nope", "", "rk4,,rk4", "dopri5", "euler"],
    "--rtols": ["1e-3,1e-6", "0", "-1", "nan", "", "1e-3,", "1e-400"],
    "--steps": ["0.01", "0", "-1", "nan", "", "1e-400", "0.05,0.1"],
    "--gains": ["1,5", "0", "-1", "", "nan"],
    "--scheduler": ["tcp://127.0.0.1:1", "", "::::", "tcp://[::1"],
    "--workers": ["0", "-1", "4097", "x", ""],  # (and 1 in the long run)
    "--sample": ["0", "1", "2", "-1", "1e3", "10000001", "x"],
    "--seed": ["0", "-1", "1" + "0" * 30, "x"],
    "--batch-size": ["1", "0", "-1", "1000001", "x"],
    "--repeats": ["1", "0", "101", "x"],
    "--timeout": ["1", "0", "-1", "nan", "1e-300"],
    "--depth": ["0", "1", "-1", "x", "1000000"],
    "--max-steps": ["0", "1", "10", "-1", "1" + "0" * 16, "x"],
}
OUTPUT_OPTIONS = {"-o", "--events", "--plot", "--json", "--bode", "--trajectories"}
INPUT_OPTIONS = {"--reference", "--input", "--data"}
PATH_OPTIONS = OUTPUT_OPTIONS | INPUT_OPTIONS
DIRECTORIES = {"accuracy": {"-o": "accdir"}, "sweep": {"--trajectories": "trajdir"}}
# settings that would make a legitimate run long (many rows, many steps): left at their
# values in the base line when another option could combine with them
HEAVY = {"--dt", "--step", "--t-end", "--max-step"}


def _options(command: str) -> list:
    """click's options of a command: [(names, kind, choices)], kind one of flag, choice,
    number, string."""
    import click

    from bgc.cli import main
    out = []
    for p in main.commands[command].params:
        if not isinstance(p, click.Option):
            continue
        if p.is_flag:
            kind = "flag"
        elif isinstance(p.type, click.Choice):
            kind = "choice"
        elif isinstance(p.type, (click.types.IntParamType, click.types.FloatParamType)) \
                or type(p.type).__name__ in ("_Number", "IntRange", "FloatRange"):
            kind = "number"
        else:
            kind = "string"
        out.append((p.opts, kind, list(getattr(p.type, "choices", []) or [])))
    return out


def _value(rng: random.Random, name: str, kind: str, choices: list, quick: bool) -> str:
    if kind == "choice":
        return rng.choice(choices + list(CHOICE_JUNK)) if rng.random() < 0.6 else \
            rng.choice(choices)
    if name in INPUT_OPTIONS:  # (not the FIFO: without a writer it waits for one, as any
        return rng.choice(INPUT_PATHS)  # reader does)
    if name in PATH_OPTIONS:
        return rng.choice(PATHS)
    if name in STRING_VALUES:
        pool = list(STRING_VALUES[name])
        if name == "--workers" and not quick and rng.random() < 0.2:
            return "1"  # a local Dask cluster of one worker
        return rng.choice(pool) if rng.random() < 0.8 else rng.choice(NAMES + NUMBERS)
    if kind == "number":
        if name in HEAVY:  # extremes, but not a legitimate run of 10^8 rows
            return rng.choice([v for v in NUMBERS if v not in (
                "1e-12", "1e-3", "1e-300", "4.9e-324", "10000001", "4096", "4097")])
        return rng.choice(NUMBERS)
    return rng.choice(NAMES + NUMBERS)


def options(rng: random.Random, quick: bool = False) -> list[str]:
    """One case: a command line (without `bgc`), from a valid one changed 1 to 4 times;
    quick: no accuracy, a sweep in Python (the suite's short campaign)."""
    commands = sorted(c for c in BASE if not (quick and c in SLOW))
    command = rng.choice(commands)
    argv = list(BASE[command])
    if quick and command == "sweep":  # (the suite's: no standalone C build of its own)
        argv += ["--backend", "python"]
    opts = _options(command)
    for _ in range(rng.choice([1, 1, 1, 2, 2, 3, 4])):
        how = rng.random()
        names, kind, choices = rng.choice(opts)
        name = rng.choice(names)
        if how < 0.55:  # an option set (or set again: a repeated option)
            if kind == "flag":
                argv.append(name)
            else:
                value = _value(rng, name, kind, choices, quick)
                if name in HEAVY and any(h in argv for h in HEAVY - {name}):
                    value = "0.5"
                if rng.random() < 0.2 and name.startswith("--"):
                    argv.append(f"{name}={value}")
                else:
                    argv += [name, value]
        elif how < 0.65:  # an option given twice
            pairs = [k for k, a in enumerate(argv) if a.startswith("-") and k + 1 < len(argv)]
            if pairs:
                k = rng.choice(pairs)
                argv += argv[k:k + 2]
        elif how < 0.75:  # a token removed (an option's value, the model, the command)
            if len(argv) > 1:
                del argv[rng.randrange(1, len(argv))]
        elif how < 0.85:  # the model argument something else
            k = argv.index("m.bg") if "m.bg" in argv else 1
            argv[k:k + 1] = [rng.choice(["missing.bg", "adir", "nulldev", "link", "", "-",
                                         "empty.bg", "m.bg", "--", "m.bg m.bg"])]
        elif how < 0.88:  # an output aimed at a file the command reads
            _aim_at_input(rng, command, argv, opts)
        elif how < 0.91:  # one output option or two given `-`
            outs = [n for names, _, _ in opts for n in names[:1] if n in OUTPUT_OPTIONS]
            for name in rng.sample(outs, min(len(outs), rng.choice([1, 1, 2]))):
                argv += [name, "-"]
        elif how < 0.95:  # an unknown option, or an option of another command
            argv.append(rng.choice(["--nope", "-x", "--t-end=", "--", "-pR=3", "--help",
                                    "--grid", "--solver", "-o", "--version", "-h"]))
        else:  # an option's value where another option should be
            argv.insert(rng.randrange(1, len(argv) + 1), rng.choice(NUMBERS + NAMES))
    return argv


def _aim_at_input(rng: random.Random, command: str, argv: list[str], opts) -> None:
    """One output of the command line aimed at a file it reads: the model becomes lm.bg
    (a library, a table; simulate also gets --input), and an output option's value one of
    those files, a link to one, or a directory whose file for that option is a hard link."""
    if "m.bg" in argv:
        argv[argv.index("m.bg")] = "lm.bg"
    if command == "simulate":
        argv += ["--input", rng.choice(["inp.csv", "inp-link.csv"])]
    if command == "accuracy" and rng.random() < 0.5:
        argv += ["--reference", rng.choice(["ref.csv", "ref-link.json"])]
    outs = [n for names, _, _ in opts for n in names[:1] if n in OUTPUT_OPTIONS]
    if not outs:
        return
    name = rng.choice(outs)
    folder = DIRECTORIES.get(command, {}).get(name)
    argv += [name, folder if folder and rng.random() < 0.7 else rng.choice(AT_INPUTS)]


# ------------------------------------------------------------------------- one case

def _setup(directory: Path) -> dict:
    """The case's directory: the models, an empty model, a directory, a symbolic link to the
    model, one to a regular file, the files lm.bg reads and the CSVs of the options that
    read (FILES) with links to them (SYMLINKS, HARDLINKS), a FIFO, private null and full
    devices (when mknod is allowed).  Returns {path: (kind, detail, inode)} to check
    afterwards."""
    (directory / "m.bg").write_text(MODEL, encoding="utf-8")
    (directory / "lm.bg").write_text(READING, encoding="utf-8")
    (directory / "empty.bg").write_text("")
    for name in ("adir", "accdir", "trajdir"):
        (directory / name).mkdir()
    (directory / "target.csv").write_text("t,x\n0,1\n")
    for name, text in FILES.items():
        (directory / name).write_text(text, encoding="utf-8")
    os.symlink("m.bg", directory / "link")
    os.symlink("target.csv", directory / "target-link.csv")
    for link, target in SYMLINKS.items():
        os.symlink(target, directory / link)
    for link, target in HARDLINKS.items():
        os.link(directory / target, directory / link)
    os.mkfifo(directory / "fifo")
    for name, minor in (("nulldev", 3), ("fulldev", 7)):
        try:
            os.mknod(directory / name, 0o666 | stat.S_IFCHR, os.makedev(1, minor))
        except OSError:
            pass
    return _snapshot(directory)


def _snapshot(directory: Path) -> dict:
    """{path relative to directory: (kind, detail, inode)} for every path in it and in its
    subdirectories; a regular file's detail is its bytes (the case's files are small)."""
    out = {}
    for root, dirs, files in os.walk(directory):
        for name in dirs + files:
            p = Path(root) / name
            st = os.lstat(p)
            key = str(p.relative_to(directory))
            if stat.S_ISLNK(st.st_mode):
                out[key] = ("link", os.readlink(p), st.st_ino)
            elif stat.S_ISDIR(st.st_mode):
                out[key] = ("dir", None, st.st_ino)
            elif stat.S_ISFIFO(st.st_mode):
                out[key] = ("fifo", None, st.st_ino)
            elif stat.S_ISCHR(st.st_mode):
                out[key] = ("chr", st.st_rdev, st.st_ino)
            elif stat.S_ISREG(st.st_mode) and st.st_size < 1 << 20:
                out[key] = ("file", p.read_bytes(), st.st_ino)
            else:
                out[key] = ("other", None, st.st_ino)
    return out


def _reads(argv: list[str], directory: Path) -> set[int]:
    """The inodes of the regular files the command line reads: its model (lm.bg's library
    and table with it), and the values of --input, --data and --reference."""
    names = {_model_argument(argv)}
    for k, a in enumerate(argv):
        name, eq, value = a.partition("=")
        if name in INPUT_OPTIONS:
            names.add(value if eq else (argv[k + 1] if k + 1 < len(argv) else ""))
    inodes = set()
    for name in names:
        try:
            info = os.stat(directory / name) if name else None
        except (OSError, ValueError):
            continue
        if info is not None and stat.S_ISREG(info.st_mode):
            inodes.add(info.st_ino)
            if name in ("lm.bg", "./lm.bg"):
                inodes |= {os.stat(directory / f).st_ino for f in ("parts.bg", "curve.csv")}
    return inodes


class _Drain:
    """Reads the FIFO while the command runs (a writer of it must not wait for a reader)."""

    def __init__(self, path: Path):
        self.fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        self.stop = False
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        while not self.stop:
            ready, _, _ = select.select([self.fd], [], [], 0.05)
            if ready:
                try:
                    if not os.read(self.fd, 1 << 16):
                        time.sleep(0.01)  # (no writer at the moment)
                except BlockingIOError:
                    pass

    def close(self):
        self.stop = True
        self.thread.join()
        os.close(self.fd)


def _model_argument(argv: list[str]) -> str:
    """The command line's MODEL as click would take it: its first token after the command
    that is neither an option nor an option's value ("" if none)."""
    if not argv or argv[0] not in BASE:
        return ""
    takes = {n for names, kind, _ in _options(argv[0]) if kind != "flag" for n in names}
    k = 1
    while k < len(argv):
        a = argv[k]
        if a == "--":
            return argv[k + 1] if k + 1 < len(argv) else ""
        if a.startswith("-") and a != "-":
            k += 2 if a in takes else 1
            continue
        return a
    return ""


def _output_values(argv: list[str], last: bool = True) -> list[str]:
    """The values given to output options: the last of each (the one click keeps), or all."""
    out = {}
    for k, a in enumerate(argv):
        name, eq, value = a.partition("=")
        if name in OUTPUT_OPTIONS:
            value = value if eq else (argv[k + 1] if k + 1 < len(argv) else "")
            out[name if last else k] = value
    return list(out.values())


def _named_outputs(argv: list[str]) -> set[str]:
    """The first path component of each value given to an output option (`-` names none:
    it is standard output)."""
    out = set()
    for value in _output_values(argv, last=False):
        if value == "-":
            continue
        first = Path(value).parts[:1]
        out.add(first[0] if first else "*")  # (".": a directory option's files go here)
    return out


def run_case(argv: list[str], env: dict | None = None) -> dict:
    """`bgc ARGV` in a directory of its own (_setup), in this process; {"exit", "stderr",
    "failure"}: failure None or what broke the promise."""
    from click.testing import CliRunner

    from bgc.cli import main

    cwd = os.getcwd()
    with tempfile.TemporaryDirectory(prefix="bgcopt-") as tmp:
        d = Path(tmp)
        before = _setup(d)
        reads = _reads(argv, d)
        drain = _Drain(d / "fifo")
        os.chdir(d)
        try:
            result = CliRunner().invoke(main, argv, env=env)
        finally:
            os.chdir(cwd)
            drain.close()
        after = _snapshot(d)
        failure = _judge(argv, result, before, after, d, reads)
    out = result.stdout + result.stderr
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        out += "".join(traceback.format_exception(result.exception))
    return {"exit": result.exit_code, "stderr": out[-3000:], "failure": failure}


def _judge(argv, result, before, after, d: Path, reads=frozenset()) -> str | None:
    command = argv[0] if argv else ""
    exc = result.exception
    if exc is not None and not isinstance(exc, SystemExit):
        frames = traceback.extract_tb(exc.__traceback__)
        inside = [f for f in frames if f"{os.sep}bgc{os.sep}" in f.filename]
        f = (inside or frames)[-1] if (inside or frames) else None
        where = f"{Path(f.filename).name}:{f.name}" if f else "?"
        return f"{command}: {type(exc).__name__} at {where}"
    code = result.exit_code
    if "Traceback (most recent call last)" in result.stdout + result.stderr:
        return f"{command}: traceback in the output"
    if code not in (0, 1, 2):
        return f"{command}: exit {code}"
    if code != 0 and not result.stderr.strip():
        return f"{command}: exit {code} without a message"
    for name, (kind, detail, inode) in before.items():
        now = after.get(name)
        if now is None:
            return f"{command}: {name} ({kind}) removed"
        if now[0] != kind:
            return f"{command}: {name} ({kind}) replaced by a {now[0]}"
        if kind in ("link", "chr") and now[1] != detail:
            return f"{command}: {name} changed"
        if kind == "file" and inode in reads and now[1:] != (detail, inode):
            return f"{command}: {name}, a file it reads, " + (
                "replaced" if now[2] != inode else "changed")
    new = [n for n in after if n not in before]
    for name in new:
        if any(part.startswith(".") for part in Path(name).parts):
            return f"{command}: a hidden file left behind ({name})"
        if Path(name).name == "-" and not any(
                v != "-" and Path(v).name == "-" for v in _output_values(argv)):
            return f"{command}: a file named '-' ({name}; standard output was meant)"
    if code == 2 and new:
        return f"{command}: a file written by a usage error ({new[0]})"
    named = _named_outputs(argv)
    for name in new:
        if Path(name).parts[0] not in named and "*" not in named:
            return f"{command}: a file it was not asked to write ({name})"
    if code == 0 and "-" in _output_values(argv) and not result.stdout_bytes:
        return f"{command}: an output given '-' and nothing on stdout"
    for p in [d / n for n in new] + [d / "target.csv"]:
        if p.is_file() and p.suffix == ".csv" and p.stat().st_size \
                and not p.read_bytes().endswith(b"\n"):
            return f"{command}: a CSV that ends in a cut row ({p.name})"
    return None


# ------------------------------------------------------------------------- the worker

def _worker_main():
    import bgc.cli  # noqa: F401
    out = os.fdopen(os.dup(1), "w")
    os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
    sys.stdout = sys.stderr
    for line in sys.stdin:
        req = json.loads(line)
        out.write(json.dumps(run_case(req["argv"], req.get("env"))) + "\n")
        out.flush()


class Worker:
    """A process running run_case, started again after a hang or a crash."""

    def __init__(self, time_limit: float):
        self.time_limit, self.proc, self.first = time_limit, None, True

    def stop(self):
        if self.proc is not None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()
            self.proc.stdin.close()
            self.proc.stdout.close()
            self.proc = None

    def run(self, argv: list[str], env: dict) -> dict:
        if self.proc is None:
            penv = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep
                        + os.environ.get("PYTHONPATH", ""))
            self.proc = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker"],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                env=penv, start_new_session=True)
            self.first = True
        try:
            self.proc.stdin.write((json.dumps({"argv": argv, "env": env}) + "\n").encode())
            self.proc.stdin.flush()
        except BrokenPipeError:
            self.stop()
            return {"exit": None, "stderr": "", "failure": f"{argv[0]}: the worker died"}
        limit = self.time_limit + (20 if self.first else 0)
        self.first = False
        ready, _, _ = select.select([self.proc.stdout], [], [], limit)
        if not ready:
            self.stop()
            return {"exit": None, "stderr": "", "failure": f"{argv[0]}: hang"}
        line = self.proc.stdout.readline()
        if not line:
            code = self.proc.wait()
            self.stop()
            return {"exit": code, "stderr": "", "failure": f"{argv[0]}: the worker died"}
        return json.loads(line)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cases", type=int, default=1000)
    ap.add_argument("--time-limit", type=float, default=60.0, help="seconds per case")
    ap.add_argument("--max-seconds", type=float, default=0,
                    help="stop (with the summary) after this many seconds (0: no limit)")
    ap.add_argument("--out", type=Path, default=Path("fuzz-options-out"))
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        _worker_main()
        return 0

    def stop(signum, frame):
        raise KeyboardInterrupt
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    a.out.mkdir(parents=True, exist_ok=True)
    cache = a.out / "cache"  # (one compile cache for the campaign: the programs built once)
    env = {"BGC_CACHE_DIR": str(cache.resolve()),
           "BGC_CFLAGS": os.environ.get("BGC_CFLAGS", "-O0 -std=c99")}
    rng = random.Random(a.seed)
    worker = Worker(a.time_limit)
    statuses: dict[str, dict[str, int]] = {}
    failures: dict[str, dict] = {}
    start = time.monotonic()
    done = 0
    log = open(a.out / "failures.txt", "a", encoding="utf-8")
    try:
        for i in range(a.cases):
            if a.max_seconds and time.monotonic() - start > a.max_seconds:
                break
            args = options(rng)
            res = worker.run(args, env)
            done += 1
            by = statuses.setdefault(args[0] if args else "", {})
            by[str(res["exit"])] = by.get(str(res["exit"]), 0) + 1
            if res["failure"]:
                entry = failures.setdefault(res["failure"], {"count": 0, "first_case": i,
                                                             "argv": args})
                entry["count"] += 1
                log.write(f"case {i}: {res['failure']}\n  bgc {' '.join(map(repr, args))}\n"
                          f"{res['stderr']}\n")
                log.flush()
                print(f"case {i}: FAILURE {res['failure']}: {args}", flush=True)
            if (i + 1) % 200 == 0:
                print(f"{i + 1} cases, {sum(f['count'] for f in failures.values())} failures "
                      f"({len(failures)} kinds), {time.monotonic() - start:.0f} s", flush=True)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
    finally:
        worker.stop()
        log.close()
        summary = {"seed": a.seed, "cases": done, "seconds": round(time.monotonic() - start),
                   "exit_statuses": statuses, "failures": failures}
        (a.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
        print(json.dumps(summary, indent=1))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
