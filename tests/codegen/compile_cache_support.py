"""A compiler that counts its compiles: a script that logs each compile, then runs the real compiler."""

from __future__ import annotations

import stat
from pathlib import Path
from typing import Callable

from modelgen.codegen.build import compiler


def counting_compiler(folder: Path) -> tuple[Path, Callable[[], int]]:
    """The script (for $CC) and a function giving how many compiles (``-shared`` in the arguments) it ran.

    With a file ``barrier`` holding N in ``folder``, a compile first waits
    (10 s at most) until N compiles have started: builders that race for sure.
    """
    real = compiler()
    log, barrier = folder / "compiles.log", folder / "barrier"
    script = folder / "counting-cc"
    script.write_text(f'#!/bin/sh\ncase " $* " in *" -shared "*)\n  echo "$*" >> "{log}"\n'
                      f'  if [ -f "{barrier}" ]; then i=0; while [ "$(wc -l < "{log}")" -lt "$(cat "{barrier}")" ] '
                      f'&& [ $i -lt 100 ]; do sleep 0.1; i=$((i+1)); done; fi;;\nesac\nexec {real} "$@"\n')
    script.chmod(script.stat().st_mode | stat.S_IXUSR)

    def compiles() -> int:
        return len(log.read_text().splitlines()) if log.exists() else 0

    return script, compiles
