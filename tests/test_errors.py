"""Bad models as files; each must produce exactly the diagnostic in its .err file, exit 1,
no traceback and no output file.  The commands run in this process (conftest.run_bgc: an
exception other than the command's exit fails the test); bgc as a process of its own, its
exit statuses and signals, is tests/test_faults.py's."""
from pathlib import Path

import pytest
from click.testing import CliRunner

from bgc.cli import main
from conftest import run_bgc

ERRORS = Path(__file__).parent / "errors"
CASES = sorted(p.name for p in ERRORS.glob("*.bg"))


@pytest.mark.parametrize("name", CASES)
def test_error_case(name, golden, monkeypatch):
    monkeypatch.chdir(ERRORS.parent.parent)
    path = f"tests/errors/{name}"
    result = CliRunner().invoke(main, ["check", path])
    assert result.exit_code == 1, result.output
    assert "Traceback" not in result.stderr
    assert result.stderr.startswith(f"{path}:"), result.stderr
    golden(ERRORS / name.replace(".bg", ".err"), result.stderr)


def test_no_output_file_on_model_error(tmp_path):
    out = tmp_path / "out.csv"
    bad = ERRORS / "causal_conflict.bg"
    for cmd in (["simulate", str(bad), "-o", str(out)], ["compile", str(bad), "-o", str(out)]):
        proc = run_bgc(*cmd)
        assert proc.returncode == 1
        assert "Traceback" not in proc.stderr
        assert "error: causal conflict" in proc.stderr
        assert not out.exists()
    assert list(tmp_path.iterdir()) == []


def test_usage_error_exit_2(tmp_path):
    proc = run_bgc("simulate")
    assert proc.returncode == 2


def test_missing_file_is_not_a_traceback(tmp_path):
    proc = run_bgc("check", tmp_path / "nope.bg")
    assert proc.returncode in (1, 2) and "Traceback" not in proc.stderr
