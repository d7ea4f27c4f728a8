"""The command line answers at once (issue 47): ``geodesics --help``, ``geodesics CMD --help``
for every command and ``geodesics metrics`` import none of the heavy modules the commands
use (scipy.integrate, torch, hypothesis, cvxpy, the Newton and IPOPT solvers, learn).

Each case runs in a fresh interpreter (a subprocess: this test process has imported them
all), invokes the typer app in-process as the console script does, and reports which of
those modules ``sys.modules`` holds afterwards. Timing is measured by
``benchmarks/cli_startup.py``, not here."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

#: Modules none of the light invocations may import.
HEAVY = ("scipy.integrate", "torch", "hypothesis", "cvxpy", "solvers.geodesic.solve",
         "solvers.newton.energy", "pinocchio", "learn.midpoint.trainer", "validation.testing")

_PROBE = r"""
import io, json, sys, contextlib
from validation.cli import app
import typer.main
args = json.loads(sys.argv[1])
if args == ["--list"]:
    print(json.dumps(sorted(typer.main.get_command(app).commands)))
    raise SystemExit(0)
out = io.StringIO()
code = 0
with contextlib.redirect_stdout(out):
    try:
        app(args=args, standalone_mode=False)
    except SystemExit as stop:
        code = stop.code or 0
heavy = json.loads(sys.argv[2])
print(json.dumps({"code": code, "chars": len(out.getvalue()),
                  "imported": [m for m in heavy if m in sys.modules]}))
"""


def _probe(args: list[str]) -> dict:
    done = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(args), json.dumps(HEAVY)],
                          capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _commands() -> list[str]:
    done = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(["--list"]), "[]"],
                          capture_output=True, text=True, timeout=120, check=True)
    return json.loads(done.stdout)


COMMANDS = _commands()


def test_every_command_is_probed():
    # the list comes from the app itself: a new command is covered without editing this file
    assert {"solve", "metrics", "check", "certify", "train", "exp"} <= set(COMMANDS)


@pytest.mark.parametrize("args", [["--help"], ["metrics"], ["metrics", "--json"]]
                         + [[c, "--help"] for c in COMMANDS], ids=" ".join)
def test_light_invocation_imports_no_heavy_module(args):
    res = _probe(args)
    assert res["code"] == 0
    assert res["chars"] > 0  # it printed its help or table
    assert res["imported"] == [], f"geodesics {' '.join(args)} imported {res['imported']}"
