"""Every command under hostile input (issues 22 and 48): hypothesis builds argument lists
from each command's options and values a hostile user would type (NaN, inf, huge, empty,
unicode, wrong dimension, outside the domain, bad paths, garbage and oversized ``.npy``
files, failing ``--metric-module`` files), and valid ones for the commands cheap enough to
run (tiny segments), and checks, in-process, that every invocation exits 0, 1 or 2
without a traceback, that an error is ONE line of at most ~200 characters, that nothing
is written outside the declared outputs (no ``__pycache__`` beside a user's module
either), that every JSON it prints (``--json``) or writes (``*.json`` files) is standard
JSON (no NaN or Infinity), that an invocation with a value that is invalid whatever else
is given never exits 0, and that a valid one is never refused. Each command has its own
budget of examples; the ``slow`` variants run five times as many, and real processes of
the installed ``geodesics``."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from validation.cli import app, main

#: Values a hostile user types where a number is expected.
NUMBERS = ["nan", "inf", "-inf", "-1", "0", "1e308", "1e-320", "2147483648", "1e23", "abc",
           "", "1_0", "٣", "0x10", "-0"]
#: ... where a point is expected (2-D metrics; some wrong dimension, some outside).
POINTS = ["0.1,0.2", "nan,0", "inf,0", "1,2,3", "", ",", "2,0", "-1e308,0", "0.1,",
          "é,1", "0.1;0.2", "1e-320,0", "0.9999999999,0", "0.1,0.2" + ",0.3" * 2000]
#: ... where a file or folder is expected (relative to the test's working folder).
PATHS = ["out.json", "x" * 300 + ".json", "missing/deep/f.json", "garbage.npy", "huge.npy",
         "pairs3d.npy", "folder", ".", "", "/proc/h22/x.json", "nul\\x00.json", "é.json",
         "file.txt/inner.json"]
METRICS = ["matsumoto", "euclidean", "poincare", "nosuch", "", "MATSUMOTO", "carlike"]
MODULES = ["raises.py", "syntax.py", "nul.py", "exits.py", "..", "folder", "nosuch_mod",
           "a.b..c", "missing.py"]
#: ... where a learning method's module is expected (plain.py registers none).
METHOD_MODULES = [*MODULES, "plain.py"]
SETS = ["hidden=[100000000]", "hidden=[]", "lr=nan", "nosuch=1", "epochs=-1", "=", "env=x",
        "hidden=[\"a\"]", "timesteps=1e400"]

#: Per command: option -> candidate values. Commands whose valid runs take long (train,
#: sweep, report, certify, log, solve with --pairs) always get at least one hostile value.
OPTIONS: dict[str, dict[str, list[str]]] = {
    "metrics": {"--json": []},
    "cost": {"--metric": METRICS, "--start": POINTS, "--goal": POINTS,
             "--order": ["0", "-3", "5", "100000000", "x"], "--rtol": NUMBERS,
             "--metric-module": MODULES, "--metric-param": ["a=1", "height=nan", "x", "=1"],
             "--json": []},
    "exp": {"--metric": METRICS, "--start": POINTS, "--velocity": [*POINTS, "1e300,0"],
            "--t": NUMBERS, "--samples": ["2147483648", "1", "-5", "3", "x"],
            "--metric-module": MODULES, "--json": []},
    "log": {"--metric": METRICS, "--start": POINTS, "--goal": POINTS, "--tol": NUMBERS,
            "--metric-module": MODULES, "--json": []},
    "solve": {"--metric": METRICS, "--start": POINTS, "--goal": POINTS, "--pairs": PATHS,
              "--segments": ["0", "1", "-1", "100000000", "3", "x"], "--out": PATHS,
              "--tol": NUMBERS, "--workers": ["0", "-1", "x"],
              "--metric-module": MODULES, "--warm-start": PATHS,
              "--method-module": METHOD_MODULES, "--json": []},
    "certify": {"--metric": [*METRICS, "panda-pole"], "--start": POINTS, "--goal": POINTS,
                "--mesh": ["coarse", "nosuch", ""], "--h": NUMBERS,
                "--directions": ["7", "100000000", "-1"], "--target-gap": NUMBERS,
                "--time-limit": NUMBERS, "--out": PATHS, "--json": []},
    "train": {"--env": METRICS, "--out": PATHS, "--timesteps": ["0", "-5", "x", "100"],
              "--minutes": NUMBERS, "--method": ["nosuch", "seq", "pg", ""],
              "--device": ["cuda:7", "tpu", ""], "--set": SETS,
              "--metric-module": MODULES, "--method-module": METHOD_MODULES},
    "evaluate": {"--run": PATHS, "--env": METRICS, "--pairs": PATHS, "--eps": NUMBERS,
                 "--depth": ["-1", "40", "x"], "--checkpoint": ["nosuch", ""],
                 "--metric-module": MODULES, "--method-module": METHOD_MODULES, "--json": []},
    "report": {"--out": PATHS, "--env": METRICS, "--run": PATHS, "--pairs": PATHS,
               "--workers": ["0", "-1"], "--certify": ["-1", "x"],
               "--checkpoint": ["nosuch"], "--metric-module": MODULES,
               "--method-module": METHOD_MODULES},
    "sweep": {"--envs": [*METRICS, "matsumoto,nosuch", ","], "--methods": ["nosuch", ""],
              "--seeds": ["0", "-1", "x"], "--out": PATHS, "--timesteps": ["0", "-3"],
              "--workers": ["0", "-2"], "--set": SETS, "--metric-module": MODULES,
              "--method-module": METHOD_MODULES, "--json": []},
    "plot-curves": {"--out": [*PATHS, "fig.png", "fig.gif"], "--column": ["nosuch", ""]},
    "check": {"--metric": METRICS, "--metric-module": MODULES, "--run": PATHS,
              "--method-module": METHOD_MODULES,
              "--examples": ["0", "-1", "x", "2147483648"], "--seed": ["-1", "x", "1e23"],
              "--metric-param": ["a=1", "height=nan", "x", "=1"], "--json": []},
}
#: Options each command needs (drawn from the candidates above) and its positional args.
REQUIRED = {"cost": ["--metric", "--start", "--goal"], "exp": ["--metric", "--start",
            "--velocity"], "log": ["--metric", "--start", "--goal"],
            "certify": ["--metric", "--start", "--goal"], "train": ["--env", "--out"],
            "sweep": ["--envs", "--methods", "--seeds", "--out"], "report": ["--out"],
            "plot-curves": ["--out"], "solve": ["--metric"], "check": ["--metric"]}
POSITIONAL = {"plot-curves": PATHS}
#: Hostile values guaranteed in long-running commands: one option gets one of these.
POISON = {"--start": "nan,0", "--goal": "2,0", "--metric": "nosuch", "--env": "nosuch",
          "--out": "x" * 300, "--envs": "nosuch", "--pairs": "huge.npy", "--run": "folder",
          "--timesteps": "-5", "--seeds": "-1", "--tol": "nan", "--h": "1e23",
          "--metric-module": "raises.py", "--set": "hidden=[100000000]"}
HEAVY = {"train", "sweep", "report", "certify", "log", "evaluate", "check"}
#: Outputs a command may write (any path given to these options, and what hangs off it).
OUTPUT_OPTIONS = ("--out",)

MODULE_FILES = {"raises.py": "raise RuntimeError('boom ' * 50)\n",
                "syntax.py": "def f(:\n",
                "nul.py": "x = 1\x00\n",
                "exits.py": "import sys\nsys.exit(3)\n",
                "plain.py": "X = 1\n"}


def make_workdir(root: Path) -> None:
    """The files the hostile values refer to."""
    for name, text in MODULE_FILES.items():
        (root / name).write_text(text)
    (root / "garbage.npy").write_bytes(b"\x93NUMPY garbage \x00\xff" * 3)
    hdr = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 2, 2), }"
    hdr = hdr + " " * (118 - len(hdr)) + "\n"
    (root / "huge.npy").write_bytes(b"\x93NUMPY\x01\x00" + len(hdr).to_bytes(2, "little")
                                    + hdr.encode() + b"\0" * 64)
    np.save(root / "pairs3d.npy", np.zeros((2, 2, 3)))
    (root / "folder").mkdir(exist_ok=True)
    (root / "file.txt").write_text("not a folder")


def snapshot(root: Path) -> dict[str, tuple[int, int]]:
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for n in dirnames + filenames:
            p = Path(dirpath) / n
            st_ = p.lstat()
            out[str(p.relative_to(root))] = (st_.st_size, int(st_.st_mtime_ns))
    return out


#: Valid values of the commands cheap enough to run for real (tiny segments), 2-D metrics.
VALID_POINTS = ["0.1,0.2", "0.25,0.1", "-0.2,0.05", "0,0.25"]  # Matsumoto: Finsler for |p| < 0.2887
VALID: dict[str, dict[str, list[str]]] = {
    "metrics": {"--json": []},
    "cost": {"--metric": ["poincare", "euclidean", "matsumoto"], "--start": VALID_POINTS,
             "--goal": VALID_POINTS, "--order": ["3", "8"], "--rtol": ["1e-8", "1e-5"],
             "--json": []},
    "exp": {"--metric": ["poincare", "euclidean", "matsumoto"], "--start": VALID_POINTS,
            "--velocity": ["0.1,0", "0,0.1", "-0.05,0.02"], "--t": ["1", "0.5"],
            "--samples": ["3", "9"], "--json": []},
    "log": {"--metric": ["poincare", "euclidean"], "--start": VALID_POINTS,
            "--goal": VALID_POINTS, "--tol": ["1e-8", "1e-6"], "--json": []},
    "solve": {"--metric": ["poincare", "euclidean", "matsumoto"], "--start": VALID_POINTS,
              "--goal": VALID_POINTS, "--segments": ["3", "4", "6"], "--out": ["out.json"],
              "--tol": ["1e-8", "1e-6"], "--json": []},
}
REQUIRED_VALID = {**REQUIRED, "solve": ["--metric", "--start", "--goal"]}
#: Examples per command in the default run (the ``slow`` variants: SLOW_FACTOR times as
#: many); cheap commands get more, about half of them valid.
BUDGET = {"metrics": 2, "cost": 24, "exp": 16, "log": 12, "solve": 24, "certify": 10,
          "train": 10, "evaluate": 10, "report": 10, "sweep": 10, "plot-curves": 8,
          "check": 10}
SLOW_FACTOR = 5

_NUM_BAD = {"nan", "-inf", "abc", "", "0x10"}
_MODULES_BAD = set(MODULES)
_IN_PATHS_BAD = {"garbage.npy", "huge.npy", "pairs3d.npy", "", "missing/deep/f.json",
                 "file.txt/inner.json", "nul\\x00.json", "x" * 300 + ".json"}
#: option -> values that make ANY invocation invalid (it must not exit 0); points are
#: judged against the metric (:func:`point_invalid`).
INVALID: dict[str, set[str]] = {
    "--metric": {"nosuch", "", "MATSUMOTO"}, "--env": {"nosuch", "", "MATSUMOTO"},
    "--envs": {"nosuch", "", "MATSUMOTO", "matsumoto,nosuch", ","},
    "--metric-module": _MODULES_BAD, "--method-module": _MODULES_BAD,
    "--rtol": _NUM_BAD | {"inf", "-1"}, "--tol": _NUM_BAD | {"inf", "-1"},
    "--t": _NUM_BAD | {"inf"}, "--h": _NUM_BAD | {"inf", "-1", "0"},
    "--target-gap": _NUM_BAD | {"inf", "-1"}, "--time-limit": _NUM_BAD | {"-1"},
    "--eps": _NUM_BAD | {"inf", "-1"}, "--minutes": _NUM_BAD | {"-1"},
    "--segments": {"0", "-1", "x"}, "--order": {"-3", "x"}, "--samples": {"-5", "x"},
    "--workers": {"-1", "-2", "x"}, "--directions": {"-1"}, "--timesteps": {"-5", "x"},
    "--depth": {"-1", "x"}, "--seeds": {"-1", "x"}, "--examples": {"-1", "x"},
    "--seed": {"x", "1e23"}, "--certify": {"-1", "x"}, "--mesh": {"nosuch", ""},
    "--method": {"nosuch", ""}, "--methods": {"nosuch", ""}, "--device": {"tpu", ""},
    "--solver": {"nosuch", ""},
    "--set": {"lr=nan", "nosuch=1", "=", 'hidden=["a"]', "timesteps=1e400", "epochs=-1"},
    "--metric-param": {"x", "=1", "height=nan"}, "--checkpoint": {"nosuch", ""},
    "--pairs": _IN_PATHS_BAD | {"folder"}, "--run": _IN_PATHS_BAD | {"."},
    "--warm-start": _IN_PATHS_BAD | {"."},
    "--out": {"", "x" * 300, "x" * 300 + ".json", "/proc/h22/x.json", "file.txt/inner.json",
              "nul\\x00.json"},
}
#: dimension and domain of the registered metrics the lists above name
_DIMS = {"matsumoto": 2, "euclidean": 2, "poincare": 2, "carlike": 3, "panda-pole": 7}


def _inside(metric: str, p: list[float]) -> bool:
    if metric in ("matsumoto", "carlike"):
        return math.hypot(p[0], p[1]) <= 1.0 and (metric == "matsumoto"
                                                  or abs(p[2]) <= math.pi)
    if metric == "poincare":
        return math.hypot(p[0], p[1]) <= 0.8
    if metric == "euclidean":
        return max(abs(x) for x in p) <= 1.0
    return True


def point_invalid(text: str, metric: str | None, in_domain: bool = True) -> bool:
    """A point no metric of that name accepts: not numbers, not finite, the wrong
    dimension, or (``in_domain``: a start or a goal) outside the metric's domain."""
    if metric not in _DIMS:
        return False  # the metric itself is judged on its own
    try:
        p = [float(t) for t in text.replace(" ", "").split(",") if t != ""]
    except ValueError:
        return True
    if len(p) != _DIMS[metric] or not all(math.isfinite(x) for x in p):
        return True
    return in_domain and not _inside(metric, p)


def invalid_values(args: list[str]) -> list[str]:
    """The options of ``args`` given a value that is invalid whatever else is given."""
    pairs = {a: args[i + 1] for i, a in enumerate(args[:-1]) if a.startswith("--")
             and not args[i + 1].startswith("--")}
    metric = pairs.get("--metric")
    bad = [o for o, v in pairs.items() if v in INVALID.get(o, ())]
    if args[0] in ("cost", "exp", "log", "solve", "certify"):
        for o in ("--start", "--goal", "--velocity"):
            if o in pairs and "--metric-module" not in pairs and point_invalid(
                    pairs[o], metric, in_domain=o != "--velocity"):
                bad.append(o)
    return bad


@st.composite
def invocations(draw: st.DrawFn, cmd: str) -> list[str]:
    """An argument list for ``cmd``: valid (commands in VALID, about half the time: its
    required options and a few more, values from VALID) or hostile (values drawn from the
    hostile lists; heavy commands: at least one poisoned)."""
    if cmd in VALID and draw(st.booleans()):
        opts = VALID[cmd]
        chosen = list(REQUIRED_VALID.get(cmd, []))
        extra = [o for o in opts if o not in chosen]
        chosen += draw(st.lists(st.sampled_from(extra), max_size=3, unique=True))
        args = [cmd]
        for o in chosen:
            args += [o] if not opts[o] else [o, draw(st.sampled_from(opts[o]))]
        return [*args, "--no-progress"] if cmd == "solve" else args
    opts = OPTIONS[cmd]
    chosen = list(REQUIRED.get(cmd, []))
    extra = [o for o in opts if o not in chosen]
    chosen += draw(st.lists(st.sampled_from(extra), max_size=3, unique=True)) if extra else []
    values = {o: (draw(st.sampled_from(opts[o])) if opts[o] else None) for o in chosen}
    if cmd in HEAVY:
        poisonable = [o for o in chosen if o in POISON]
        if not poisonable:  # none of the drawn options can be poisoned: add one that can
            o = draw(st.sampled_from([o for o in opts if o in POISON]))
            chosen.append(o)
            poisonable = [o]
        o = draw(st.sampled_from(poisonable))
        values[o] = POISON[o]
    args = [cmd]
    for o in chosen:
        args += [o] if values[o] is None else [o, values[o]]
    if cmd in POSITIONAL:
        args.append(draw(st.sampled_from(POSITIONAL[cmd])))
    if cmd == "solve" and draw(st.booleans()):
        args += ["--no-progress"]
    return args


def is_valid(args: list[str]) -> bool:
    """Every token of ``args`` from VALID (a valid invocation of a cheap command)."""
    opts = VALID.get(args[0])
    if opts is None:
        return False
    tokens = {args[0], "--no-progress", *opts}
    for values in opts.values():
        tokens.update(values)
    return all(a in tokens for a in args) and all(
        o in args for o in REQUIRED_VALID.get(args[0], []))


def _refuse_constant(name: str) -> None:
    raise ValueError(f"{name} in JSON output (not standard JSON)")


def strict_json(text: str) -> object:
    """``json.loads`` that refuses NaN, Infinity and -Infinity."""
    return json.loads(text, parse_constant=_refuse_constant)


def declared_outputs(args: list[str]) -> list[str]:
    outs = [args[i + 1] for i, a in enumerate(args[:-1]) if a in OUTPUT_OPTIONS]
    if args[0] == "plot-curves":  # the figure's numbers go beside it
        outs += [str(Path(o).with_suffix(".csv")) for o in outs if Path(o).name]
    return outs


def _changed_json(root: Path, before: dict[str, tuple[int, int]]) -> list[str]:
    """The ``*.json`` files under ``root`` new or changed since ``before``."""
    after = snapshot(root)
    return [rel for rel, st_ in after.items() if rel.endswith(".json")
            and before.get(rel) != st_ and (root / rel).is_file()]


def check_outcome(root: Path, args: list[str], code: int, stderr: str,
                  before: dict[str, tuple[int, int]], usage_blocks: bool = True,
                  stdout: str = "") -> None:
    """The bars of issues 22 and 48 for one invocation. ``usage_blocks``: typer's boxed
    usage errors are accepted (the in-process app); the ``geodesics`` console script
    (:func:`validation.cli.main`) turns them into one ``error:`` line too."""
    shown = " ".join(a[:40] for a in args)
    assert code in (0, 1, 2), (shown, code, stderr[-2000:])
    assert "Traceback" not in stderr, (shown, stderr[-3000:])
    bad = invalid_values(args)
    assert not (bad and code == 0), (shown, f"exit 0 with invalid {bad}", stderr[-1000:])
    if "--json" in args and code in (0, 1) and stdout.strip():
        try:
            strict_json(stdout)
        except ValueError as err:
            pytest.fail(f"{shown}: --json printed no standard JSON ({err}): {stdout[:500]}")
    for rel in _changed_json(root, before):
        try:
            strict_json((root / rel).read_text())
        except (ValueError, UnicodeDecodeError) as err:
            pytest.fail(f"{shown}: wrote {rel}, not standard JSON ({err})")
    if code != 0:
        lines = [ln for ln in stderr.splitlines() if ln.strip()]
        # a result that is not the answer (exit 1) says so on stderr, not only its status
        assert lines, (shown, code, "exit code without a message on stderr")
        errors = [ln for ln in lines if ln.startswith("error: ")]
        if code == 2 and errors:
            # bad input: the one error line, nothing before it (no warnings)
            assert len(lines) == 1 and len(lines[0]) <= 210, (shown, stderr[-2000:])
        elif code == 2:  # typer's own usage errors: a usage block, no traceback
            assert usage_blocks, ("the console script printed a usage block", shown,
                                  stderr[-2000:])
            assert "Usage:" in stderr or "Error" in stderr, (shown, stderr[-2000:])
    after = snapshot(root)
    allowed = [root / o for o in declared_outputs(args) if o]
    for rel in set(after) - set(before):
        p = root / rel
        ok = any(p == a or a in p.parents or p.name.startswith(f".{a.name}")
                 or p == a.with_name(a.name + ".parts") or a.with_name(a.name + ".parts")
                 in p.parents for a in allowed)
        assert ok, (shown, rel)
        assert "__pycache__" not in rel, (shown, rel)
    for rel in before:  # nothing the command was not asked to write was changed
        if rel in after and after[rel] != before[rel]:
            p = root / rel
            assert any(p == a or a in p.parents for a in allowed), (shown, rel)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("hostile")
    make_workdir(root)
    return root


def _run_in_process(workdir: Path, args: list[str]) -> None:
    before = snapshot(workdir)
    res = CliRunner().invoke(app, args)
    if res.exception is not None and not isinstance(res.exception, SystemExit):
        import traceback

        tb = "".join(traceback.format_exception(res.exception))
        pytest.fail(f"{' '.join(a[:40] for a in args)}: traceback\n{tb[-3000:]}")
    check_outcome(workdir, args, res.exit_code, res.stderr, before, stdout=res.stdout)
    if is_valid(args):
        # a valid invocation is never refused (exit 1: a result that is not the answer)
        assert res.exit_code in (0, 1), (args, res.exit_code, res.stderr[-1000:])


def _hostile(workdir: Path, cmd: str, examples: int, run) -> None:
    @settings(max_examples=examples, deadline=None, derandomize=True, database=None,
              suppress_health_check=[HealthCheck.function_scoped_fixture,
                                     HealthCheck.too_slow])
    @given(args=invocations(cmd))
    def inner(args: list[str]) -> None:
        run(workdir, args)

    inner()


@pytest.mark.parametrize("cmd", sorted(OPTIONS))
def test_every_command_holds_under_hostile_input(workdir: Path, cmd: str,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(workdir)
    _hostile(workdir, cmd, BUDGET[cmd], _run_in_process)


@pytest.mark.slow
@pytest.mark.parametrize("cmd", sorted(OPTIONS))
def test_every_command_holds_under_wider_hostile_input(workdir: Path, cmd: str,
                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(workdir)
    _hostile(workdir, cmd, SLOW_FACTOR * BUDGET[cmd], _run_in_process)


def _run_as_process(workdir: Path, args: list[str]) -> None:
    exe = Path(sys.executable).with_name("geodesics")
    before = snapshot(workdir)
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)  # the loader itself must prevent __pycache__
    proc = subprocess.run([str(exe), *[a.replace("\x00", "") for a in args]], cwd=workdir,
                          capture_output=True, text=True, timeout=600, env=env,
                          stdin=subprocess.DEVNULL)
    check_outcome(workdir, args, proc.returncode, proc.stderr, before, usage_blocks=False,
                  stdout=proc.stdout)


@pytest.mark.slow
@pytest.mark.parametrize("cmd", sorted(OPTIONS))
def test_every_command_holds_under_hostile_input_as_a_process(workdir: Path,
                                                              cmd: str) -> None:
    _hostile(workdir, cmd, max(2, BUDGET[cmd] // 2), _run_as_process)


def test_strict_json_refuses_nan_and_infinity_and_the_invalid_table_judges_points() -> None:
    """The checks above can fail: NaN / Infinity are refused, points are judged against
    the metric's dimension and domain."""
    for text in ('{"a": NaN}', '[Infinity]', '{"b": -Infinity}'):
        with pytest.raises(ValueError):
            strict_json(text)
    assert strict_json('{"a": null, "b": 1e308}') == {"a": None, "b": 1e308}
    assert point_invalid("0.9,0", "poincare") and not point_invalid("0.9,0", "matsumoto")
    assert point_invalid("0.1,0.2", "carlike") and not point_invalid("0.1,0.2,3", "carlike")
    assert point_invalid("1e300,0", "euclidean")
    assert not point_invalid("1e300,0", "euclidean", in_domain=False)
    assert invalid_values(["cost", "--metric", "poincare", "--start", "nan,0"]) == ["--start"]
    assert invalid_values(["solve", "--metric", "poincare", "--segments", "3"]) == []


@pytest.mark.parametrize("args", [
    ["solve", "--metrc", "x"], ["solve", "--metric"], ["solve"], ["nosuchcommand"],
    ["train", "--env", "euclidean", "--out", "o", "--timesteps", "abc"],
    ["certify", "--metric", "poincare", "--start", "0,0", "--goal", "0.1,0", "--json", "x"],
])
def test_usage_errors_of_the_console_script_are_one_line(
        args: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(args)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "--help'" in err[0], err
    assert len(err[0]) <= 240


def test_console_script_help_and_no_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0 and "solve" in capsys.readouterr().out
    with pytest.raises(SystemExit) as exc:
        main([])
    out = capsys.readouterr()
    assert exc.value.code == 2 and "solve" in out.out and out.err == ""


def test_a_failed_report_leaves_no_new_folders(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """Found by the tour: `report --out missing/deep/f.json --run folder` (a folder that is
    no run) left `missing/deep/` behind."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder").mkdir()
    res = CliRunner().invoke(app, ["report", "--out", "missing/deep/f.json", "--run",
                                   "folder"])
    assert res.exit_code == 2 and "config.json" in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder"]


@pytest.mark.parametrize(("velocity", "status"), [("-0.3,0.4", "not_convex"),
                                                   ("1.0,0.0", "not_convex")])
def test_exp_that_stops_early_says_so_on_stderr(velocity: str, status: str) -> None:
    """exit 1 with the stopped curve on stdout and one line on stderr (the tour found exit
    1 without a word where the Matsumoto geodesic reaches the non-convex region)."""
    res = CliRunner().invoke(app, ["exp", "--metric", "matsumoto", "--start", "0.1,0.2",
                                   "--velocity", velocity])
    assert res.exit_code == 1
    assert f"status        {status}" in res.stdout
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("note: the geodesic stopped") \
        and status in lines[0]


def test_a_refused_warm_start_leaves_no_output_folders(tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """Found by the tour: `solve --out no/such/o.json --warm-start RUN` with a run of another
    metric created `no/such/` before refusing the warm start."""
    monkeypatch.chdir(tmp_path)
    res = CliRunner().invoke(app, ["solve", "--metric", "matsumoto", "--start", "0.1,0.2",
                                   "--goal", "0.3,0.1", "--out", "no/such/o.json",
                                   "--warm-start", "carlike"])
    assert res.exit_code == 2 and "not for 'matsumoto'" in res.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("cmd", [["report", "--env", "matsumoto"],
                                 ["train", "--env", "euclidean"],
                                 ["sweep", "--envs", "euclidean", "--methods", "midpoint",
                                  "--seeds", "1"],
                                 ["plot-curves", "."]])
def test_an_empty_out_is_refused_not_the_current_folder(
        cmd: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """Found by the tour: `report --out ''` wrote the report into the current folder
    (``Path('')`` is ``.``)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main([*cmd, "--out", ""])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1 and "--out" in err[0] and "empty" in err[0]
    assert list(tmp_path.iterdir()) == []
