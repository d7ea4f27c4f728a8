"""finsler: Finsler metrics defined once, symbolically in CasADi, with every numeric
evaluator (numpy, torch, IPOPT) derived from that single expression.

A metric's optional capabilities are declared in `finsler.hooks`; its identity (name
or class, parameters) as a [`MetricSpec`][finsler.MetricSpec] in `finsler.spec`."""

from __future__ import annotations

from typing import TYPE_CHECKING

from finsler.infra.lazy import lazy_exports

if TYPE_CHECKING:
    from finsler.domains import Box, Disk, Domain, JointBox, Product
    from finsler.errors import DomainError, InputError, UnknownMetricError
    from finsler.hooks import HOOKS, MetricHooks
    from finsler.infra.files import (
        OutputError,
        atomic_write_bytes,
        atomic_write_text,
        check_output_path,
    )
    from finsler.metrics.base import LengthBounds, LengthEstimate, Metric, Task, TrainingSettings
    from finsler.metrics.closed_form import (
        ClosedFormMetric,
        Euclidean,
        Minkowski,
        Poincare,
        PoincareSlab,
        Randers,
        Sphere,
    )
    from finsler.metrics.paper import MATSUMOTO_CONVEX_RADIUS, CarLike, Matsumoto, PandaPole
    from finsler.pairs import (
        DEFAULT_EVAL_SEED,
        VALIDATION_SEED,
        default_pairs,
        load_pairs,
        sample_pairs,
        validation_pairs,
    )
    from finsler.registry import get_metric, list_metrics, metric_class, register_metric
    from finsler.spec import MetricSpec, metric_spec

# Public names -> defining module, imported on first use (PEP 562): `import finsler` and
# `from finsler.errors import InputError` stay cheap (no CasADi, numpy) for the command line's
# --help.
_LAZY = {
    "Box": "finsler.domains",
    "CarLike": "finsler.metrics.paper",
    "ClosedFormMetric": "finsler.metrics.closed_form",
    "DEFAULT_EVAL_SEED": "finsler.pairs",
    "Disk": "finsler.domains",
    "Domain": "finsler.domains",
    "DomainError": "finsler.errors",
    "Euclidean": "finsler.metrics.closed_form",
    "HOOKS": "finsler.hooks",
    "InputError": "finsler.errors",
    "JointBox": "finsler.domains",
    "LengthBounds": "finsler.metrics.base",
    "LengthEstimate": "finsler.metrics.base",
    "MATSUMOTO_CONVEX_RADIUS": "finsler.metrics.paper",
    "Matsumoto": "finsler.metrics.paper",
    "Metric": "finsler.metrics.base",
    "MetricHooks": "finsler.hooks",
    "MetricSpec": "finsler.spec",
    "Minkowski": "finsler.metrics.closed_form",
    "OutputError": "finsler.infra.files",
    "PandaPole": "finsler.metrics.paper",
    "Poincare": "finsler.metrics.closed_form",
    "PoincareSlab": "finsler.metrics.closed_form",
    "Product": "finsler.domains",
    "Randers": "finsler.metrics.closed_form",
    "Sphere": "finsler.metrics.closed_form",
    "Task": "finsler.metrics.base",
    "TrainingSettings": "finsler.metrics.base",
    "UnknownMetricError": "finsler.errors",
    "VALIDATION_SEED": "finsler.pairs",
    "atomic_write_bytes": "finsler.infra.files",
    "atomic_write_text": "finsler.infra.files",
    "check_output_path": "finsler.infra.files",
    "default_pairs": "finsler.pairs",
    "get_metric": "finsler.registry",
    "list_metrics": "finsler.registry",
    "load_pairs": "finsler.pairs",
    "metric_class": "finsler.registry",
    "metric_spec": "finsler.spec",
    "register_metric": "finsler.registry",
    "sample_pairs": "finsler.pairs",
    "validation_pairs": "finsler.pairs",
}

__all__ = [
    "DEFAULT_EVAL_SEED",
    "HOOKS",
    "MATSUMOTO_CONVEX_RADIUS",
    "VALIDATION_SEED",
    "Box",
    "CarLike",
    "ClosedFormMetric",
    "Disk",
    "Domain",
    "DomainError",
    "Euclidean",
    "InputError",
    "JointBox",
    "LengthBounds",
    "LengthEstimate",
    "Matsumoto",
    "Metric",
    "MetricHooks",
    "MetricSpec",
    "Minkowski",
    "OutputError",
    "PandaPole",
    "Poincare",
    "PoincareSlab",
    "Product",
    "Randers",
    "Sphere",
    "Task",
    "TrainingSettings",
    "UnknownMetricError",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_output_path",
    "default_pairs",
    "get_metric",
    "list_metrics",
    "load_pairs",
    "metric_class",
    "metric_spec",
    "register_metric",
    "sample_pairs",
    "validation_pairs",
]


__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals(), __all__)
