"""The registry of learning methods: what the CLI, sweeps and ``load_policy`` read.

A method registers itself once, in the module that defines it, with
`register_method` and a `Method`: its config class, its trainer (a
[`learn.loop.RunLoop`][learn.loop.RunLoop] subclass), its policy loader, its default config and, for
sweeps, its named `Variant` s. Nothing else names it: ``geodesics train --method``,
``geodesics sweep --methods``, ``geodesics evaluate --run`` and `learn.load_policy`
find it here. The toolkit's own methods (`learn.midpoint.trainer`: midpoint / inter /
two-to-one, `learn.pg.trainer`, `learn.seq.trainer`) are imported on first need; a method in a
user's file is imported with ``--method-module FILE.py`` (`import_method_modules`)
and its module is recorded in each run's ``config.json`` (``method_module``, and the file
in ``method_file``) so that loading the run re-imports it (when it is importable; else the
error names the file to pass with ``--method-module``). The shipped example
`learn.examples.toy_method` is such a method (``--method-module
learn.examples.toy_method``).

What a loaded policy offers every command is the protocol `PathPolicy` (and
`MidpointPolicy` for a policy that predicts midpoints); `learn.train_run`
trains any registered method's config ([`Method.train`][learn.registry.Method.train]).
"""

from __future__ import annotations

import difflib
import importlib
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from finsler.errors import InputError
from finsler.infra.modules import import_user_module

if TYPE_CHECKING:
    import numpy as np

    import finsler

__all__ = [
    "BUILTIN_MODULES",
    "Method",
    "MidpointPolicy",
    "PathPolicy",
    "Variant",
    "deprecated_entry",
    "find_variant",
    "get_method",
    "import_method_modules",
    "list_methods",
    "method_of_run",
    "register_method",
    "unregister_method",
    "variants",
]

#: The toolkit's own method modules, imported (in this order) when a name is not yet
#: registered: each registers its methods on import.
BUILTIN_MODULES = ("learn.midpoint.trainer", "learn.seq.trainer", "learn.pg.trainer")


@runtime_checkable
class PathPolicy(Protocol):
    """What a method's ``load_policy`` returns (a `learn.base.LoadedPolicy` has the
    attributes): the policy of a run, which every command that reads runs (``geodesics
    evaluate``, ``report``, ``check --run``, ``solve --warm-start``) uses through these
    names only. ``isinstance(policy, PathPolicy)`` checks that they are there."""

    metric: finsler.Metric
    """The metric the policy was trained on (with the run's parameters)."""
    config: Any
    """The run's config (a [`learn.run_config.RunConfig`][learn.run_config.RunConfig])."""
    depth: int
    """The depth D of its paths (``2**D`` segments) unless asked otherwise."""
    eps: float
    """Its success threshold."""
    source: str
    """The run directory (or shipped policy) it came from."""
    checkpoint: str
    """The checkpoint file its weights came from."""

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """Paths ``(K, dim)`` x2 -> ``(K, 2**D + 1, dim)`` float64 from the starts to the
        goals (D = ``depth`` or the policy's)."""
        ...

    def evaluate(self, pairs: Any = None, eps: float | None = None,
                 depth: int | None = None) -> Any:
        """Section 5.1 evaluation on ``pairs`` ``(K, 2, dim)`` (default:
        ``finsler.default_pairs``): a `learn.evaluation.EvalResult`."""
        ...


@runtime_checkable
class MidpointPolicy(PathPolicy, Protocol):
    """A `PathPolicy` that predicts midpoints (every midpoint-tree method: the
    midpoint learner, PG, the example; Seq walks step by step and has none): the midpoint
    checks of ``geodesics check`` and the reports' midpoint errors use it."""

    def midpoint(self, starts: Any, goals: Any) -> np.ndarray:
        """Predicted midpoints ``(K, dim)`` of the pairs (``(dim,)`` for one pair)."""
        ...


@dataclass(frozen=True)
class Variant:
    """A named configuration of a method for sweeps and comparisons: ``make(env,
    **fields)`` returns the config (``fields``: seed, timesteps, minutes, device and any
    overrides)."""

    summary: str
    make: Callable[..., Any]


@dataclass(frozen=True)
class Method:
    """A learning method as the registry knows it.

    ``config_methods``: the values of the config's ``method`` field this entry trains
    (default: ``name`` alone; the midpoint learner also trains ``inter`` and
    ``two-to-one``). ``variants``: named configurations for sweeps (default: ``name`` ->
    ``default_config``). ``presets``: command-line switches of ``geodesics train`` mapped
    to variants (the midpoint learner's ``paper`` and ``model-free``).
    """

    name: str
    summary: str
    config_class: type
    trainer: type
    """A `learn.loop.RunLoop` subclass: ``trainer(cfg, out, resume=, progress=)``."""
    load_policy: Callable[..., Any]
    """``load_policy(run_dir, checkpoint=, device=, env=, metric_params=)`` -> a
    `PathPolicy` (a `MidpointPolicy` if it predicts midpoints)."""
    default_config: Callable[..., Any]
    """``default_config(env, **fields)`` -> the method's config."""
    config_methods: tuple[str, ...] = ()
    variants: Mapping[str, Variant] = field(default_factory=dict)
    presets: Mapping[str, str] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.config_methods:
            object.__setattr__(self, "config_methods", (self.name,))
        if not self.variants:
            object.__setattr__(self, "variants",
                               {self.name: Variant(self.summary, self.default_config)})

    @property
    def module(self) -> str:
        """The module that defines the method's trainer (re-imported to load its runs)."""
        return self.trainer.__module__

    @property
    def builtin(self) -> bool:
        """True for the toolkit's own methods (imported on first need); a method of any
        other module (the shipped example `learn.examples.toy_method` too) is
        imported by name in sweep workers and recorded in its runs' ``config.json``."""
        return self.module in BUILTIN_MODULES

    def train(self, cfg: Any, out: str | Path, resume: bool = False,
              progress: bool = True) -> Any:
        """Train ``cfg`` into run directory ``out``: the `learn.base.TrainResult`
        (what [`learn.train_run`][learn.train_run] calls for ``cfg.method``)."""
        return self.trainer(cfg, out, resume=resume, progress=progress).run()


_METHODS: dict[str, Method] = {}


def deprecated_entry(name: str) -> None:
    """Warn (`DeprecationWarning`, at the caller's line) that ``name()``, one
    method's own training function, is deprecated for the one entry point
    [`learn.train_run`][learn.train_run]."""
    warnings.warn(f"{name}() is deprecated: use learn.train_run(cfg, out, resume=..., "
                  "progress=...), the one entry point that trains every method's config",
                  DeprecationWarning, stacklevel=3)


def register_method(method: Method) -> Method:
    """Register ``method`` under each of its ``config_methods`` (re-registering a name
    replaces it; a variant name already taken by another method is an error)."""
    if not isinstance(method, Method):
        raise InputError(f"register_method needs a learn.registry.Method, got "
                         f"{type(method).__name__}")
    for other in _distinct_methods():
        if other.name == method.name:
            continue
        taken = set(other.variants) & set(method.variants)
        if taken:
            raise InputError(f"method {method.name!r}: variant(s) {', '.join(sorted(taken))} "
                             f"already belong to method {other.name!r}")
    for name in method.config_methods:
        _METHODS[name] = method
    return method


def unregister_method(name: str) -> None:
    """Remove the method registered under ``name`` (all of its ``config_methods``), e.g.
    after a test; an unknown name is an `InputError`."""
    if name not in _METHODS:
        raise InputError(f"method {name!r} is not registered")
    method = _METHODS[name]
    for key in method.config_methods:
        if _METHODS.get(key) is method:
            del _METHODS[key]


def _import_builtins(until: str | None = None) -> None:
    """Import the toolkit's method modules (all, or until ``until`` is registered)."""
    for module in BUILTIN_MODULES:
        if until is not None and until in _METHODS:
            return
        importlib.import_module(module)


def get_method(name: str) -> Method:
    """The method whose config ``method`` value is ``name`` (`InputError` with the
    registered names otherwise)."""
    if not isinstance(name, str):
        raise InputError(f"method must be a name, got {name!r}")
    if name not in _METHODS:
        _import_builtins(until=name)
    if name not in _METHODS:
        known = list_methods()
        close = difflib.get_close_matches(name, known, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise InputError(f"unknown method {name!r}{hint}; known: {', '.join(known)} (a "
                         "method of your own: --method-module FILE.py)")
    return _METHODS[name]


def list_methods() -> list[str]:
    """Every registered value of a config's ``method``."""
    _import_builtins()
    return list(_METHODS)


def _distinct_methods() -> list[Method]:
    """Every registered method once (a method is registered under each of its names), in
    registration order; compared by identity, nothing keyed by ``id()``."""
    out: list[Method] = []
    for m in _METHODS.values():
        if not any(m is o for o in out):
            out.append(m)
    return out


def _entries() -> Iterator[Method]:
    _import_builtins()
    yield from _distinct_methods()


def variants() -> dict[str, Variant]:
    """Every registered variant (name -> `Variant`), method by method."""
    return {name: v for m in _entries() for name, v in m.variants.items()}


def find_variant(name: str) -> tuple[Method, Variant]:
    """The method and `Variant` called ``name`` (`InputError` otherwise)."""
    for m in _distinct_methods():
        if name in m.variants:
            return m, m.variants[name]
    for m in _entries():
        if name in m.variants:
            return m, m.variants[name]
    raise InputError(f"unknown variant {name!r}; known: {', '.join(variants())} (a method "
                     "of your own: --method-module FILE.py)")


def method_of_run(run_dir: str | Path, section: Mapping[str, Any]) -> Method:
    """The method of a run directory whose ``config`` section is ``section`` (default
    ``midpoint``): registered, or registered by importing the ``method_module`` the run's
    ``config.json`` records (never its ``method_file``, which only names the file to pass
    with ``--method-module`` when the module cannot be imported)."""
    from learn.storage import CONFIG_FILE, read_json

    name = section.get("method", "midpoint")
    if isinstance(name, str) and name not in _METHODS:
        _import_builtins(until=name)
        doc = read_json(Path(run_dir) / CONFIG_FILE)
        module = doc.get("method_module")
        if name not in _METHODS and isinstance(module, str):
            try:
                import_user_module(module, f"method {name!r}: module")
            except InputError as err:
                where = doc.get("method_file")
                hint = where if isinstance(where, str) else f"FILE.py of module {module!r}"
                raise InputError(f"cannot import module {module!r} of the run's method "
                                 f"{name!r}; pass --method-module {hint}") from err
    return get_method(str(name))


def import_method_modules(items: Iterable[str] | None) -> list[str]:
    """Import every ``--method-module`` (a dotted module name, or a ``.py`` file whose
    folder is put first on ``sys.path`` and which is imported by its stem, so that worker
    processes and later loads import it by that name too); returns the module names.
    A module that registers no method (none registered while importing it, none whose
    trainer it defines) is an `InputError`."""
    names = []
    for item in items or []:
        before = dict(_METHODS)
        name = import_user_module(item, "--method-module").__name__
        added = any(_METHODS[k] is not before.get(k) for k in _METHODS)
        defines = any(m.module == name or m.module.startswith(name + ".")
                      for m in _METHODS.values())
        if not (added or defines):
            raise InputError(f"--method-module {item}: registers no learning method (call "
                             "learn.registry.register_method(Method(...)) in it)")
        names.append(name)
    return names
