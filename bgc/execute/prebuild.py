"""What an installed bgc would otherwise build on its first run, built when the package is:
the interpreter (bgc.codegen.vm), the runtime's object file that each model's C part is linked with
(bgc.base.cache.compile_runtime) and the parser's tables (bgc.front.parser), written into
DIRECTORY under the names the compile cache gives them (with their SHA-256 beside).  setup.py runs
it into the package's `prebuilt/` directory; bgc.base.cache copies a file from there into the
cache when every input of its name (its source, the compiler and its version, the flags)
matches a run's, and builds it as before otherwise.

    python -m bgc.execute.prebuild DIRECTORY
"""
from __future__ import annotations

import os
import sys
from pathlib import Path


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python -m bgc.execute.prebuild DIRECTORY", file=sys.stderr)
        return 2
    directory = Path(argv[0]).resolve()
    directory.mkdir(parents=True, exist_ok=True)
    os.environ["BGC_CACHE_DIR"] = str(directory)
    os.environ.pop("BGC_CFLAGS", None)  # the flags a run has by default

    from ..base import cache, toolchain
    from ..codegen import emit, vm
    from ..front import parser
    parser.lark_parser()
    if not toolchain.have_c_compiler():
        print("bgc.execute.prebuild: no C compiler: the interpreter and the runtime are built on "
              "first use", file=sys.stderr)
        return 0
    try:
        vm.interpreter()
        cache.compile_runtime(emit.c_runtime_unit())
    except toolchain.BackendError as error:
        print(f"bgc.execute.prebuild: {error}: the interpreter and the runtime are built on "
              "first use", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
