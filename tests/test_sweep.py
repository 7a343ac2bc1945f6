"""Sweeps (bgc/execute/sweeps.py, the programs' --batch mode): a batch's runs equal separate runs
of the program bit for bit; a failed run is a row and leaves the others alone; Dask gives the same
table as a serial sweep, also when a worker dies in the middle."""
import math
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import bgc
from bgc import api
from bgc.base import cache, processes, toolchain
from bgc.execute import sweeps
from bgc.cli import main
from bgc.codegen.emit import emit_c, emit_python

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = str(ROOT / "models" / "pendulum.bg")
METRICS = ["final:x", "max:rod.residual", "min:y", "maxabs:rod.lambda", "rms:rod.residual"]
needs_cc = pytest.mark.skipif(not toolchain.have_c_compiler(), reason="no C compiler")


@pytest.fixture(scope="module")
def swing():
    return api.build(PENDULUM, "swing")


def _metrics_from_csv(csv_text):
    """The metrics, computed here from a separate run's CSV (rms: per row, in row order)."""
    lines = csv_text.splitlines()
    names = lines[0].split(",")
    cols = {n: [float(row.split(",")[k]) for row in lines[1:]] for k, n in enumerate(names)}
    out = {}
    for spec in METRICS:
        kind, _, name = spec.partition(":")
        v = cols[name]
        if kind == "final":
            out[spec] = v[-1]
        elif kind == "max":
            out[spec] = max(v)
        elif kind == "min":
            out[spec] = min(v)
        elif kind == "maxabs":
            out[spec] = max(abs(a) for a in v)
        else:
            total = 0.0
            for a in v:
                total += a * a
            out[spec] = math.sqrt(total / len(v))
    return out


@needs_cc
def test_batch_equals_separate_runs_bit_for_bit(swing):
    table = bgc.sweep(swing, sample=20, vary={"m": "uniform(0.5,2)", "l": "normal(1,0.05)",
                                              "alpha": "loguniform(1,50)"},
                      seed=3, metrics=METRICS, batch_size=7)
    assert len(table) == 20 and table.failures() == 0
    (source,) = emit_c(swing.program).values()
    exe = cache.compile_c(source)
    for i in range(20):
        params = {n: float(table[n][i]) for n in ("m", "l", "alpha")}
        code, out, err = processes.run_c(exe, api.run_args(params=params) + ["--stats"])
        assert code == 0, err
        for spec, value in _metrics_from_csv(out).items():
            assert table[spec][i] == value, (i, spec)  # bit for bit
        steps, rejected, rhs = (int(err.split(f"{k}=")[1].split()[0])
                                for k in ("steps", "rejected", "rhs"))
        assert (table["steps"][i], table["rejected"][i], table["rhs"][i]) == \
            (steps, rejected, rhs)


def test_python_batch_equals_separate_runs(swing):
    (text,) = emit_python(swing.program).values()
    module = processes.load_python_module(text)
    runs = ["alpha=2.5 m=1.5", "", "# a comment, no run", "l=1.25"]
    rows = module.batch(runs, METRICS, t_end=0.5)
    assert [r["run"] for r in rows] == [0, 1, 2]
    for row, params in zip(rows, [{"alpha": 2.5, "m": 1.5}, {}, {"l": 1.25}]):
        t, Y = module.simulate(t_end=0.5, params=params)
        csv = "\n".join([",".join(["t"] + module.OUTPUTS)] + [
            ",".join("%.17g" % v for v in [a, *y]) for a, y in zip(t, Y)])
        assert row["status"] == "ok" and row["message"] == ""
        for spec, value in _metrics_from_csv(csv).items():
            assert row[spec] == value


@needs_cc
def test_a_failed_run_is_a_row_and_the_others_are_unaffected(swing):
    """rk4 at the scene's dt with alpha = 1e7 blows up (|1 - h alpha| >> 1): status failed."""
    options = dict(solver="rk4", t_end=1.0)
    mixed = bgc.sweep(swing, grid={"alpha": [5.0, 1e7, 20.0]}, metrics=METRICS,
                      batch_size=2, **options)
    good = bgc.sweep(swing, grid={"alpha": [5.0, 20.0]}, metrics=METRICS, **options)
    assert mixed["status"] == ["ok", "failed", "ok"]
    assert "is not finite" in mixed["message"][1] and mixed["message"][0] == ""
    assert all(math.isnan(mixed[m][1]) for m in METRICS)
    for m in METRICS + ["steps", "rhs"]:
        assert list(mixed[m][[0, 2]]) == list(good[m])
    # a line the program cannot read is a row too (the batch goes on)
    (source,) = emit_c(swing.program).values()
    run = sweeps.run_batch(sweeps.make_program(source, "", ("--t-end", "0.1"), ()), 0,
                           ("nosuch=1", "alpha=1e999", "alpha=2"))
    assert [r[0] for r in run.rows] == ["invalid", "invalid", "ok"]
    assert run.rows[0][-1] == "unknown parameter 'nosuch'"


def test_grid_and_sample_specifications():
    name, values = sweeps.parse_grid_axis("alpha=1:100:log3")
    assert name == "alpha" and values == pytest.approx([1.0, 10.0, 100.0], rel=1e-15)
    assert sweeps.parse_grid_axis("l=0.5:1:lin3")[1] == [0.5, 0.75, 1.0]
    assert sweeps.parse_grid_axis("l=0.5,1,2")[1] == [0.5, 1.0, 2.0]
    names, runs = sweeps.grid_runs([("a", [1.0, 2.0]), ("b", [3.0, 4.0, 5.0])])
    assert names == ["a", "b"] and runs[:4] == [(1.0, 3.0), (1.0, 4.0), (1.0, 5.0), (2.0, 3.0)]
    assert sweeps.parse_distribution("m = normal(1, 0.05)".replace(" ", "")) == \
        ("m", "normal", 1.0, 0.05)
    for bad in ("m=eval(1,2)", "m=uniform(2,1)", "m=uniform(1)", "m=__import__('os')",
                "m=uniform(1,2)+1", "=uniform(1,2)"):
        with pytest.raises(sweeps.SweepError):
            sweeps.parse_distribution(bad)
    for bad in ("a=1:2:log0", "a=0:2:log3", "a=1,,2", "a=", "a=x", "a=1:2:lin"):
        with pytest.raises(sweeps.SweepError):
            sweeps.parse_grid_axis(bad)
    _, a = sweeps.sample_runs(50, [("m", "uniform", 0.5, 2.0), ("l", "normal", 1.0, 0.05)], 1)
    _, b = sweeps.sample_runs(50, [("m", "uniform", 0.5, 2.0), ("l", "normal", 1.0, 0.05)], 1)
    rng = np.random.default_rng(1)
    assert a == b and [r[0] for r in a] == list(rng.uniform(0.5, 2.0, 50))
    assert all(0.5 <= r[0] < 2.0 for r in a)


@needs_cc
def test_cli_sweep_table_and_trajectories(tmp_path, monkeypatch):
    monkeypatch.setattr(sweeps, "have_dask", lambda: False)
    runner = CliRunner()
    out, traj = tmp_path / "t.csv", tmp_path / "runs"
    args = ["sweep", PENDULUM, "--scene", "swing", "--grid", "alpha=1:10:log2", "--grid",
            "beta=2,3", "--metric", "final:x", "--t-end", "0.5", "-o", str(out),
            "--trajectories", str(traj), "--no-timing"]
    result = runner.invoke(main, args)
    assert result.exit_code == 0, result.output
    assert "running the batches serially" in result.stderr
    lines = out.read_text().splitlines()
    assert lines[0] == "run,alpha,beta,final:x,steps,rejected,rhs,status,message"
    assert [line.split(",")[:3] for line in lines[1:]] == [
        ["0", "1", "2"], ["1", "1", "3"], ["2", "10", "2"], ["3", "10", "3"]]
    assert sorted(os.listdir(traj)) == [f"run-{i:06d}.csv" for i in range(4)]
    single = tmp_path / "one.csv"
    result = runner.invoke(main, ["simulate", PENDULUM, "--scene", "swing", "--t-end", "0.5",
                                  "-p", "alpha=10", "-p", "beta=3", "-o", str(single)])
    assert result.exit_code == 0
    assert (traj / "run-000003.csv").read_bytes() == single.read_bytes()
    # the same table as Parquet: the same columns and values (pyarrow reads it back)
    try:
        import pyarrow.parquet as pq
    except ImportError:
        pq = None
    if pq is not None:
        pq_out = tmp_path / "t.parquet"
        result = runner.invoke(main, args[:-5] + ["-o", str(pq_out), "--no-timing"])
        assert result.exit_code == 0, result.output
        read = pq.read_table(pq_out).to_pydict()
        assert list(read) == lines[0].split(",")
        for i, line in enumerate(lines[1:]):
            cells = line.split(",")
            assert read["run"][i] == int(cells[0]) and read["status"][i] == cells[7]
            assert read["final:x"][i] == float(cells[3])  # %.17g: the same double
    monkeypatch.setattr(sweeps, "have_pyarrow", lambda: False)
    result = runner.invoke(main, args[:-5] + ["-o", str(tmp_path / "u.parquet")])
    assert result.exit_code == 2 and "pip install 'bgc[parquet]'" in result.output
    assert not (tmp_path / "u.parquet").exists()
    for bad in (["--grid", "alpha=1:2:log"], ["--sample", "3"], ["--grid", "alpha=1",
                "--sample", "2"], ["--grid", "nosuch=1"], ["--grid", "alpha=1", "-p",
                "alpha=2"], ["--grid", "alpha=1", "--metric", "max:nosuch"]):
        result = runner.invoke(main, ["sweep", PENDULUM, *bad])
        assert result.exit_code == 2, (bad, result.output)
        assert "Traceback" not in result.output


# ---------------------------------------------------------------- Dask

@pytest.fixture(scope="module")
def client():
    pytest.importorskip("distributed")
    c = sweeps.local_client(2)
    yield c
    cluster = c.cluster
    c.close()
    cluster.close()


GAINS = {"alpha": "1:50:log20", "beta": "1:50:lin10"}  # 200 runs


@pytest.fixture(scope="module")
def serial_table(swing):
    return bgc.sweep(swing, grid=GAINS, metrics=METRICS, t_end=1.0, timing=False,
                     batch_size=200)


@needs_cc
def test_dask_table_is_the_serial_table(swing, client, serial_table):
    table = bgc.sweep(swing, grid=GAINS, metrics=METRICS, t_end=1.0, timing=False,
                      client=client, batch_size=17)
    assert len(table) == 200 and table.to_csv() == serial_table.to_csv()


@needs_cc
def test_a_worker_killed_mid_sweep_leaves_the_table_complete(swing, client, serial_table):
    killed = []

    def kill_a_busy_worker(progress):
        if killed:
            return
        busy = [w for w, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)  # lost, not closed: its tasks are rescheduled
            killed.append(busy[0])

    table = bgc.sweep(swing, grid=GAINS, metrics=METRICS, t_end=1.0, timing=False,
                      client=client, batch_size=5, progress=kill_a_busy_worker)
    assert killed, "no worker was busy after the first batch"
    assert table.to_csv() == serial_table.to_csv()
