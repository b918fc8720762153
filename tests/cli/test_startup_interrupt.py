"""Ctrl-C while the command line loads: one line and 130, not a traceback (tune's soak
sent SIGINT 2 s into a run and got xarray's import traceback and a process killed by it)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

# The interpreter runs ``python -m fsmbench.cli tune ...`` with one of the command line's
# imports interrupted as a Ctrl-C would (the signal's KeyboardInterrupt raised inside it).
_SCRIPT = """
import builtins, runpy, sys
real = builtins.__import__
def interrupted(name, *args, **kwargs):
    if name == "fsmbench.cli.commands":
        raise KeyboardInterrupt
    return real(name, *args, **kwargs)
builtins.__import__ = interrupted
sys.argv = ["fsmbench", "tune", "--device", "ca://NOWHERE", "--out", "never"]
runpy.run_module("fsmbench.cli", run_name="__main__")
"""


def test_ctrl_c_while_the_command_loads_is_one_line_and_130(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True,
                          timeout=300, cwd=str(tmp_path))
    assert done.returncode == 130, done.stderr[-1500:]
    assert "Traceback" not in done.stderr
    assert "interrupted (Ctrl-C) while starting" in done.stderr
    assert "nothing was changed" in done.stderr


def test_a_ctrl_c_after_the_command_has_returned_stops_nothing() -> None:
    # The console script's teardown (a device proxy's, threads) runs with SIGINT ignored:
    # a Ctrl-C there killed a tune that had written and said its result (status -2). An
    # exit handler reads the disposition the interpreter's teardown runs under.
    code = ("import atexit, os, signal, sys\n"
            "def at_exit():\n"
            "    ignored = signal.getsignal(signal.SIGINT) is signal.SIG_IGN\n"
            "    os.kill(os.getpid(), signal.SIGINT)\n"
            "    sys.stdout.flush()\n"
            "    os._exit(0 if ignored else 3)\n"
            "atexit.register(at_exit)\n"
            "sys.argv = ['fsmbench', 'params', '--json']\n"
            "from fsmbench.cli import console\n"
            "console()\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=False)
    assert done.returncode == 0, (done.returncode, done.stderr[-2000:])
    assert json.loads(done.stdout)["format"] == "fsmbench.params"
