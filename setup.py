"""The package's build, as pyproject.toml declares it, with one step more: once the package is
laid out, bgc.execute.prebuild compiles what a first run would otherwise build (the interpreter, the
runtime's object file, the parser's tables) into its `prebuilt/` directory, so that the first
`bgc simulate` of an installed bgc compiles no runtime.  Without a C compiler, or in an
editable install, nothing is prebuilt and bgc builds them on first use, as before."""
import os
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyPrebuilt(build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False) or os.environ.get("BGC_NO_PREBUILD"):
            return
        lib = Path(self.build_lib).resolve()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [str(lib), *filter(None, [os.environ.get("PYTHONPATH")])]))
        try:
            subprocess.run([sys.executable, "-m", "bgc.execute.prebuild",
                            str(lib / "bgc" / "prebuilt")], env=env, check=True, timeout=900)
        except (OSError, subprocess.SubprocessError) as error:
            print(f"warning: bgc.execute.prebuild failed ({error}): bgc builds its runtime on "
                  "first use", file=sys.stderr)


setup(cmdclass={"build_py": BuildPyPrebuilt})
