"""The engine of the property suite: a hypothesis search for a counterexample, shrunk within
a budget of evaluations, and the result it reports.

A property is a strategy of examples and a check that judges one example and returns a
:class:`Verdict` (the two sides compared, and whether the example holds, fails, or lies in
a region the metric documents, which is *mapped* rather than failed). :func:`search` runs
hypothesis on it (``hypothesis.find``: generation, then shrinking of the first failing
example) and returns a :class:`PropertyResult`: examples tried and passed, and for a
failure the smallest failing example hypothesis reached, with the values on both sides.

Checks can be expensive (a property of solved distances solves geodesics), so every
verdict is cached by the example's value, and shrinking stops evaluating new examples
after ``shrink_limit`` evaluations: the result then is the smallest failing example among
those evaluated (a budget of work, not of seconds, so the result depends on the seed
only).
"""

from __future__ import annotations

import random
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from hypothesis import HealthCheck, Phase, Verbosity, find, settings
from hypothesis.errors import NoSuchExample, Unsatisfiable
from hypothesis.strategies import SearchStrategy

from finsler.errors import InputError
from validation.jsonout import jsonable as _jsonable
from validation.text import text_table

__all__ = [
    "FAILED",
    "MAPPED",
    "PASSED",
    "SKIPPED",
    "CheckReport",
    "PropertyFailure",
    "PropertyResult",
    "Verdict",
    "search",
    "seeded",
]

PASSED, FAILED, MAPPED, SKIPPED = "passed", "failed", "mapped", "skipped"


class PropertyFailure(AssertionError):
    """A property does not hold; the message is :meth:`PropertyResult.describe`."""

    def __init__(self, result: PropertyResult) -> None:
        super().__init__(result.describe())
        self.result = result


@dataclass(frozen=True)
class Verdict:
    """The judgement of one example.

    ``lhs`` / ``rhs``: the two sides compared, each ``(label, value)``; ``relation`` how
    they must compare (``"<="``, ``"=="``, ...). ``ok``: the example holds. ``mapped``:
    the example lies where the metric documents that the property does not apply (a
    non-convex region): it neither passes nor fails, it is counted and reported.
    ``note``: what else a reader needs (tolerances, statuses, an exception).
    """

    ok: bool
    lhs: tuple[str, Any] | None = None
    rhs: tuple[str, Any] | None = None
    relation: str = ""
    note: str = ""
    mapped: bool = False

    @classmethod
    def compare(cls, lhs: tuple[str, Any], relation: str, rhs: tuple[str, Any],
                ok: bool, note: str = "") -> Verdict:
        return cls(bool(ok), lhs, rhs, relation, note)


@dataclass
class PropertyResult:
    """What one property found.

    ``status``: ``passed`` (no counterexample among ``tried`` examples), ``failed`` (a
    counterexample, shrunk), ``mapped`` (failures or examples only inside a region the
    metric documents as excluded, e.g. where ``F(x, .)`` is not convex; ``note`` says
    where) or ``skipped`` (does not apply to this metric; ``note`` says why).
    ``tried`` examples were generated and judged (shrinking not counted), ``passed`` of
    them held and ``mapped`` were in the documented region. ``counterexample`` maps names
    to values (floats, lists); ``lhs`` / ``rhs`` are the two sides at it.
    ``shrink_evaluations`` counts the examples judged while shrinking.
    """

    name: str
    claim: str
    status: str
    tried: int = 0
    passed: int = 0
    mapped: int = 0
    counterexample: dict[str, Any] | None = None
    lhs: tuple[str, Any] | None = None
    rhs: tuple[str, Any] | None = None
    relation: str = ""
    note: str = ""
    shrink_evaluations: int = 0
    shrink_limited: bool = False
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        """True unless the property failed."""
        return self.status != FAILED

    def assert_ok(self) -> None:
        """Raise :class:`PropertyFailure` (an ``AssertionError``) if the property failed."""
        if not self.ok:
            raise PropertyFailure(self)

    def sides(self) -> str:
        """``"lhs = a  <=  rhs = b"`` at the counterexample, or ``""``."""
        if self.lhs is None or self.rhs is None:
            return ""

        def side(s: tuple[str, Any]) -> str:
            value = fmt(s[1])
            return s[0] if s[0] == value else f"{s[0]} = {value}"

        return f"{side(self.lhs)}   {self.relation or 'vs'}   {side(self.rhs)}"

    def short_example(self, width: int = 60) -> str:
        """The counterexample on one line (truncated to ``width`` characters)."""
        if not self.counterexample:
            return "-"
        text = " ".join(f"{k}={fmt(v)}" for k, v in self.counterexample.items())
        return text if len(text) <= width else text[: width - 3] + "..."

    def describe(self) -> str:
        """A few lines for a reader: the property, its claim, the counterexample (shrunk)
        and the values on both sides."""
        head = f"{self.status.upper()} {self.name}: {self.claim}"
        lines = [head, f"  examples tried {self.tried}, passed {self.passed}"
                 + (f", in the mapped region {self.mapped}" if self.mapped else "")]
        if self.counterexample:
            how = (f"shrunk in {self.shrink_evaluations} evaluations"
                   + (", shrink budget reached" if self.shrink_limited else ""))
            lines.append(f"  counterexample ({how}):")
            lines += [f"    {k} = {fmt(v, 12)}" for k, v in self.counterexample.items()]
        if self.sides():
            lines.append(f"  {self.sides()}")
        if self.note:
            lines.append(f"  {self.note}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        def side(s: tuple[str, Any] | None) -> dict[str, Any] | None:
            return None if s is None else {"label": s[0], "value": jsonable(s[1])}

        return {"name": self.name, "claim": self.claim, "status": self.status,
                "tried": self.tried, "passed": self.passed, "mapped": self.mapped,
                "counterexample": jsonable(self.counterexample), "lhs": side(self.lhs),
                "relation": self.relation, "rhs": side(self.rhs), "note": self.note,
                "shrink_evaluations": self.shrink_evaluations,
                "shrink_limited": self.shrink_limited, "seconds": round(self.seconds, 3)}


@dataclass
class CheckReport:
    """Every property checked on one metric (and policy): :meth:`table` for people,
    :meth:`to_dict` for JSON; ``ok`` is False if any property failed."""

    metric: str
    params: dict[str, Any]
    seed: int
    examples: int
    results: list[PropertyResult] = field(default_factory=list)
    policy: str | None = None
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return all(r.ok for r in self.results)

    @property
    def failed(self) -> list[PropertyResult]:
        return [r for r in self.results if not r.ok]

    def table(self) -> str:
        """The property table (property, examples tried, passed, result, counterexample)
        followed by the details of every failed or mapped property."""
        head = ("property", "tried", "passed", "result", "counterexample")
        rows = [head] + [(r.name, str(r.tried), str(r.passed), r.status, r.short_example())
                         for r in self.results]
        lines = [text_table(rows)]
        details = [r.describe() for r in self.results if r.status in (FAILED, MAPPED)]
        reasons: dict[str, list[str]] = {}
        for r in self.results:
            if r.status == SKIPPED:
                reasons.setdefault(r.note, []).append(r.name)
        skipped = [f"  {', '.join(names)}: {note}" for note, names in reasons.items()]
        if details:
            lines += ["", *details]
        if skipped:
            lines += ["", "skipped:", *skipped]
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        return {"metric": self.metric, "params": jsonable(self.params), "policy": self.policy,
                "seed": self.seed, "examples": self.examples, "ok": self.ok,
                "failed": [r.name for r in self.failed], "seconds": round(self.seconds, 3),
                "properties": [r.to_dict() for r in self.results]}


def jsonable(v: Any) -> Any:
    """Numbers, arrays and containers as JSON-ready Python values (non-finite -> str)."""
    return _jsonable(v, nonfinite_as_text=True)


def fmt(v: Any, digits: int = 6) -> str:
    """A value for a table or a message: floats to ``digits`` significant digits,
    vectors as tuples."""
    if isinstance(v, (list, tuple, np.ndarray)):
        return "(" + ", ".join(fmt(x, digits) for x in np.asarray(v).reshape(-1)) + ")"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):.{digits}g}"
    return str(v)


def seeded(seed: int, stream: str) -> random.Random:
    """A ``random.Random`` for one search, fixed by the check's ``seed`` and a stream name
    (string seeds hash by SHA-512: the same on every run and machine)."""
    return random.Random(f"{int(seed)}/{stream}")


def _key(value: Any) -> Any:
    """A hashable key of an example (arrays by their bytes)."""
    if isinstance(value, np.ndarray):
        return ("a", value.shape, value.dtype.str, value.tobytes())
    if isinstance(value, (tuple, list)):
        return tuple(_key(v) for v in value)
    if isinstance(value, float):
        return ("f", value.hex())
    return value


def _judge(check: Callable[[Any], Verdict], example: Any) -> Verdict:
    try:
        out = check(example)
    except (KeyboardInterrupt, SystemExit, MemoryError):
        raise
    except Exception as err:  # the metric (or solver) raised: that is the finding
        msg = " ".join(str(err).split())
        return Verdict(False, note=f"raised {type(err).__name__}: {msg[:300]}")
    if not isinstance(out, Verdict):
        raise TypeError(f"a property check must return a Verdict, got {type(out).__name__}")
    return out


def search(
    name: str,
    claim: str,
    strategy: SearchStrategy[Any],
    check: Callable[[Any], Verdict],
    describe: Callable[[Any], dict[str, Any]],
    *,
    examples: int,
    rng: random.Random,
    shrink_limit: int = 400,
) -> PropertyResult:
    """Search ``strategy`` for an example that ``check`` fails (at most ``examples``
    generated), shrink the first one found (at most ``shrink_limit`` new evaluations)
    and return the result. ``describe`` names the parts of an example for the report.
    Deterministic for a given ``rng`` state."""
    t0 = time.perf_counter()
    if isinstance(examples, bool) or not isinstance(examples, (int, np.integer)) or examples < 1:
        raise InputError(f"examples must be a positive integer, got {examples!r}")
    cache: dict[Any, Verdict] = {}
    state = {"tried": 0, "passed": 0, "mapped": 0, "shrinks": 0, "failed": False,
             "limited": False}

    def condition(example: Any) -> bool:
        k = _key(example)
        verdict = cache.get(k)
        if verdict is None:
            if state["failed"]:
                if state["shrinks"] >= shrink_limit:
                    state["limited"] = True
                    return False  # budget spent: not evaluated, so not a counterexample
                state["shrinks"] += 1
            verdict = _judge(check, example)
            cache[k] = verdict
            if not state["failed"]:
                state["tried"] += 1
                if verdict.ok and verdict.mapped:
                    state["mapped"] += 1
                elif verdict.ok:
                    state["passed"] += 1
            if not verdict.ok:
                state["failed"] = True
        return not verdict.ok

    opts = settings(max_examples=int(examples), database=None, deadline=None,
                    derandomize=False, phases=(Phase.generate, Phase.shrink),
                    suppress_health_check=list(HealthCheck), verbosity=Verbosity.quiet)
    found: Any = None
    unsatisfiable = False
    try:
        found = find(strategy, condition, settings=opts, random=rng)
    except NoSuchExample:
        found = None
    except Unsatisfiable:
        unsatisfiable = True
    res = PropertyResult(name=name, claim=claim, status=PASSED, tried=state["tried"],
                         passed=state["passed"], mapped=state["mapped"],
                         shrink_evaluations=state["shrinks"], shrink_limited=state["limited"])
    if found is not None:
        v = cache[_key(found)]
        res.status = FAILED
        res.counterexample = describe(found)
        res.lhs, res.rhs, res.relation, res.note = v.lhs, v.rhs, v.relation, v.note
    elif unsatisfiable or res.tried == 0:
        res.status = SKIPPED
        res.note = "no valid example could be generated"
    elif res.mapped:
        res.status = MAPPED
    res.seconds = time.perf_counter() - t0
    return res


def combine(name: str, claim: str, parts: Sequence[PropertyResult]) -> PropertyResult:
    """One result from searches of the same property on several regions: failed if any
    failed (its counterexample), else mapped if any mapped, else passed; counts summed."""
    order = {FAILED: 0, MAPPED: 1, PASSED: 2, SKIPPED: 3}
    first = min(parts, key=lambda r: order[r.status])
    out = PropertyResult(name=name, claim=claim, status=first.status,
                         tried=sum(r.tried for r in parts), passed=sum(r.passed for r in parts),
                         mapped=sum(r.mapped for r in parts),
                         counterexample=first.counterexample, lhs=first.lhs, rhs=first.rhs,
                         relation=first.relation,
                         shrink_evaluations=sum(r.shrink_evaluations for r in parts),
                         shrink_limited=any(r.shrink_limited for r in parts),
                         seconds=sum(r.seconds for r in parts))
    out.note = " ".join(r.note for r in parts if r.note)
    return out
