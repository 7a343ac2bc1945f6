import os
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"


def pytest_addoption(parser):
    parser.addoption("--update-golden", action="store_true", default=False,
                     help="Rewrite golden files (tests/golden, tests/errors/*.err) from the "
                          "current output instead of comparing with them.")


@pytest.fixture
def golden(request):
    """golden(path, text): compare text with the file, or rewrite it under --update-golden."""
    update = request.config.getoption("--update-golden")

    def check(path: Path, text: str):
        if update or not path.exists():
            if not update:
                pytest.fail(f"golden file {path.relative_to(ROOT)} is missing: run "
                            "pytest --update-golden and review the diff")
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text, encoding="utf-8")
            return
        expected = path.read_text(encoding="utf-8")
        assert text == expected, f"{path.relative_to(ROOT)} differs (pytest --update-golden " \
                                 "rewrites it; read the diff first)"
    return check


def have_cc() -> bool:
    return shutil.which(os.environ.get("CC", "cc")) is not None
