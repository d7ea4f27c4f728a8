"""``geodesics report --quick`` on a user's metric without a shipped policy: it says first
that it trains (budget, time), and SIGINT or SIGTERM while it trains ends with exit 130, one
line of its own on stderr (after the progress bar's), no traceback, no report, and a run
that the same command resumes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

BUMP = '''
from dataclasses import dataclass
from typing import ClassVar
import casadi as ca
from finsler import Disk, Metric, Task, register_metric

@register_metric
@dataclass(frozen=True)
class Bump(Metric):
    """F(x, v) = (1 + a exp(-|x|^2 / 0.1)) |v| on the unit disk."""
    a: float = 2.0
    name: ClassVar[str] = "bump_interrupt"
    task: ClassVar[Task] = Task(depth=5, eps=0.2)
    reversible: ClassVar[bool] = True
    domain = property(lambda self: Disk(radius=1.0))
    def F_sx(self, x, v):
        return (1 + self.a * ca.exp(-ca.dot(x, x) / 0.1)) * ca.sqrt(ca.dot(v, v))
'''


def _report_until(tmp: Path, sig: int, after: float) -> tuple[int, str, str]:
    """Start the report, wait for its first line and ``after`` seconds more, send ``sig``."""
    cmd = [sys.executable, "-m", "validation.cli", "report", "--env", "bump_interrupt",
           "--metric-module", "bump.py", "--quick", "--out", "rep"]
    proc = subprocess.Popen(cmd, cwd=tmp, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"},
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    first = proc.stdout.readline()  # said before anything is trained
    time.sleep(after)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=120)  # bytes: the bar's \r stay \r
    return proc.returncode, (first + out).decode(), err.decode()


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_report_says_it_trains_and_stops_cleanly(tmp_path: Path) -> None:
    (tmp_path / "bump.py").write_text(BUMP)
    code, out, err = _report_until(tmp_path, signal.SIGINT, 6.0)
    assert out.startswith("no shipped policy for 'bump_interrupt': training one first (3e+06 "
                          "evaluations of C, typically 2-5 minutes"), out
    lines = err.replace("\r", "\n").strip().split("\n")
    assert code == 130, err
    assert err.count("\n") <= 2 and "Traceback" not in err, err
    assert lines[-1].startswith("interrupted (SIGINT) while training the --quick policy: it is "
                                "kept in rep/quick_run at ")
    run = tmp_path / "rep" / "quick_run"
    assert (run / "config.json").is_file() and not (run / "result.json").exists()
    assert not (tmp_path / "rep" / "report.md").exists()
    code, out, err = _report_until(tmp_path, signal.SIGTERM, 3.0)  # the same command resumes
    assert out.startswith("resuming the interrupted --quick training"), out
    assert code == 130 and "Traceback" not in err and err.count("\n") <= 2, err
    assert "interrupted (SIGTERM)" in err
