"""`bgc simulate --plot`: the columns' kinds and units, the CSV reader, the figure written
atomically after the run (a failed run's rows too), and the checks before any work."""
import sys

import pytest

import bgc
from bgc.reports import plot
from conftest import MODELS, have_cc, run_bgc

PNG = b"\x89PNG\r\n\x1a\n"
BACKEND = "c" if have_cc() else "python"

UNITS = """model units "a motor"
parameter V = 2 "supply [V]"
parameter r = 1
parameter kt = 0.5
parameter J = 0.1 "inertia [kg m^2]"
src : Se(V)
elec : 1 "armature current [A]"
res : R(r)
ind : I(0.2)
gy : GY(kt)
shaft : 1 "speed [rad/s]"
rotor : I(J) "the rotor"
src -> elec
elec -> res
elec -> ind
elec -> gy -> shaft
shaft -> rotor
signal angle = integral(shaft.f, init = 0)
"""


def test_columns_kinds_docs_and_units():
    compiled = bgc.build(bgc.api.Source("units.bg", UNITS), program=False)
    names = ["ind.f", "elec.f", "rotor.f", "ind.p", "rotor.p", "angle", "J", "V"]
    cols = {c.name: c for c in plot.columns(compiled, names)}
    assert [cols[n].kind for n in names] == ["f", "f", "f", "p", "p", "signal", "parameter",
                                             "parameter"]
    # a 1-junction's doc gives its flow's unit, and the flow of a one-port bonded to it
    assert cols["elec.f"].unit == "A" and cols["ind.f"].unit == "A"
    assert cols["rotor.f"].unit == "rad/s" and cols["rotor.f"].doc == "the rotor"
    assert cols["rotor.p"].unit is None and cols["J"].unit == "kg m^2"
    assert cols["J"].doc == "inertia"
    groups = [(kind, [c.name for c in group])
              for kind, group in plot.panels([cols[n] for n in names])]
    assert groups == [("unit", ["ind.f", "elec.f"]), ("unit", ["rotor.f"]),
                      ("p", ["ind.p", "rotor.p"]), ("signal", ["angle"]),
                      ("unit", ["J"]), ("unit", ["V"])]


def test_panels_group_by_unit_before_kind():
    """Outputs of one unit share a panel whatever they are (a flow, a signal, a component's
    parameter); the others are grouped by kind.  x, the integral of a voltage, is in V*s
    (Wb, from the units check: bgc.front.units), a panel of its own; the capacitor's charge
    has no known unit (C(1): a number of any unit)."""
    text = ('model m\ncomponent src(v = 1 unit "V") { port p; s : Se(v); s -> p }\n'
            'a : src(v = 2)\nn : 0 "node [V]"\nc : C(1)\na.p -> n\nn -> c\n'
            'signal half = c.e/2 unit "V"\nsignal x = integral(c.e, init = 0)\n')
    compiled = bgc.build(bgc.api.Source("m.bg", text), program=False)
    names = ["a.v", "c.q", "c.e", "half", "x"]
    groups = [(kind, [c.name for c in group])
              for kind, group in plot.panels(plot.columns(compiled, names))]
    assert groups == [("unit", ["a.v", "c.e", "half"]), ("q", ["c.q"]), ("unit", ["x"])]
    assert plot.columns(compiled, ["x"])[0].unit == "Wb"


def test_an_inputs_unit_is_its_columns():
    """`input NAME = DEFAULT unit "UNIT" "doc"`: the input's column is in that unit, on the
    panel of the signals of that unit; w and y, of no declared unit, take x's through the
    sum y = w + x (the units check), z none."""
    text = ('model m\ninput u = 1 unit "V" "the drive"\ninput w\ninput z\n'
            'parameter tau = 1 unit "s"\n'
            'signal x = integral((u - x)/tau, init = 0) unit "V"\nsignal y = w + x\n'
            'signal v = 2*z\n')
    compiled = bgc.build(bgc.api.Source("m.bg", text), program=False)
    cols = plot.columns(compiled, ["u", "x", "w", "y", "z"])
    assert [(c.name, c.kind, c.unit) for c in cols] == [
        ("u", "signal", "V"), ("x", "signal", "V"), ("w", "signal", "V"), ("y", "signal", "V"),
        ("z", "signal", None)]
    assert [(kind, [c.name for c in group]) for kind, group in plot.panels(cols)] == [
        ("unit", ["u", "x", "w", "y"]), ("signal", ["z"])]


def test_read_csv_every_kth_row_and_the_last(tmp_path):
    path = tmp_path / "run.csv"
    rows = [f"{k},{2 * k},{k * k}" for k in range(101)]
    path.write_text("t,a,b\n" + "\n".join(rows) + "\n17,1")  # a last row cut short
    table = plot.read_csv(path, max_points=10)
    assert table.names == ("a", "b") and table.rows == 101 and table.every == 11
    assert table.t == [float(k) for k in range(0, 100, 11)] + [100.0]
    assert table.values[1] == [k * k for k in table.t]
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n1,2\n")
    with pytest.raises(plot.PlotError):
        plot.read_csv(bad)


def test_simulate_plot_to_stdout_and_failed_run(tmp_path):
    pytest.importorskip("matplotlib")
    model = str(MODELS / "pendulum.bg")
    csv = tmp_path / "p.csv"
    done = run_bgc("simulate", model, "--scene", "swing", "--t-end", "1", "--backend", BACKEND,
                   "-o", csv)
    assert done.returncode == 0, done.stderr
    png = tmp_path / "p.png"
    done = run_bgc("simulate", model, "--scene", "swing", "--t-end", "1", "--backend", BACKEND,
                   "--plot", png)
    assert done.returncode == 0, done.stderr
    assert done.stdout == csv.read_text()  # the CSV on stdout, as without --plot
    assert png.read_bytes().startswith(PNG)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.csv", "p.png"]

    # a run that fails keeps its rows, and they are plotted
    blow = tmp_path / "blow.bg"
    blow.write_text("model blow\nsignal z = integral(z^2, init = 1)\n"
                    "scene s { time 0 .. 2 every 0.1 }\n")
    done = run_bgc("simulate", blow, "--scene", "s", "--backend", BACKEND, "-o",
                   tmp_path / "blow.csv", "--plot", tmp_path / "blow.png")
    assert done.returncode == 1 and "the rows up to t = " in done.stderr
    assert (tmp_path / "blow.png").read_bytes().startswith(PNG)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no hidden files


def test_plot_run_panels(tmp_path):
    pytest.importorskip("matplotlib")
    compiled = bgc.build(MODELS / "pendulum.bg", "swing", program=False)
    path = tmp_path / "run.csv"
    path.write_text("t,x,y,rod.lambda,rod.residual\n0,1,2,3,4\n1,2,3,4,5\n")
    table = plot.read_csv(path)
    fig, drawn = plot.figure(table, plot.columns(compiled, table.names),
                             plot.title_lines(compiled), stopped=True)
    assert drawn == ["signals | x, y", "constraint multipliers | rod.lambda",
                     "constraint residuals | rod.residual"]
    assert fig._suptitle.get_text().splitlines() == [
        "pendulum: Point mass on a rigid rod, Cartesian coordinates, Baumgarte-stabilised",
        "scene swing: ten seconds of stabilised swing (eq. 12)",
        "the run stopped at t = 1: its rows up to there"]
    plot.pyplot().close(fig)


def test_plot_is_checked_before_any_work(tmp_path, monkeypatch):
    broken = tmp_path / "broken.bg"
    broken.write_text("model broken\nthis is not a model\n")
    done = run_bgc("simulate", broken, "--plot", tmp_path / "p.txt")
    assert done.returncode == 2 and ".png" in done.stderr
    done = run_bgc("simulate", broken, "--plot", tmp_path / "nowhere" / "p.png")
    assert done.returncode == 2 and "does not exist" in done.stderr
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib: ImportError
    done = run_bgc("simulate", broken, "--plot", tmp_path / "p.png")
    assert done.returncode == 2
    assert "pip install 'bgc[plot]'" in done.stderr
    assert "broken.bg:" not in done.stderr  # the model was not even read
    assert list(tmp_path.iterdir()) == [broken]
