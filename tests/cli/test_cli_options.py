"""The shared options of the ``geodesics`` commands are defined once (issue 49, item 3):
``--metric-param``, ``--metric-module`` and ``--method-module`` are declared in
``validation/cli/common.py`` only, and every command offering them uses that declaration."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import typer.main

from validation.cli import app

CLI = Path(__file__).resolve().parents[2] / "validation" / "cli"
SHARED = ("--metric-param", "--metric-module", "--method-module")


@pytest.mark.parametrize("flag", SHARED)
def test_flag_declared_in_one_module(flag: str) -> None:
    declared = [p.name for p in sorted(CLI.glob("*.py"))
                if re.search(r"typer\.Option\(\s*" + re.escape(f'"{flag}"'), p.read_text())]
    assert declared == ["common.py"]


def test_every_command_with_a_shared_flag_uses_the_same_declaration() -> None:
    click_app = typer.main.get_command(app)
    seen: dict[str, set[tuple[str | None, bool]]] = {flag: set() for flag in SHARED}
    for name, cmd in click_app.commands.items():  # type: ignore[attr-defined]
        for param in cmd.params:
            for flag in SHARED:
                if flag in getattr(param, "opts", ()):
                    seen[flag].add((param.metavar, param.multiple))
                    assert param.name == flag[2:].replace("-", "_"), (name, param.name)
    assert all(seen.values()), seen  # each flag is offered by some command
    for flag, shapes in seen.items():
        assert len(shapes) == 1, (flag, shapes)  # one metavar, repeatable everywhere
