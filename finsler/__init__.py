"""finsler: Finsler metrics defined once, symbolically in CasADi, with every numeric
evaluator (numpy, torch, IPOPT) derived from that single expression.

A metric's optional capabilities are declared in :mod:`finsler.hooks`; its identity (name
or class, parameters) as a :class:`MetricSpec` in :mod:`finsler.spec`."""

from finsler.domains import Box, Disk, Domain, JointBox, Product
from finsler.errors import DomainError, InputError, UnknownMetricError
from finsler.files import OutputError, atomic_write_bytes, atomic_write_text, check_output_path
from finsler.hooks import HOOKS, MetricHooks
from finsler.metric import LengthBounds, LengthEstimate, Metric, Task
from finsler.metrics import (
    MATSUMOTO_CONVEX_RADIUS,
    CarLike,
    ClosedFormMetric,
    Euclidean,
    Matsumoto,
    Minkowski,
    PandaPole,
    Poincare,
    Randers,
    Sphere,
)
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
    "Product",
    "Randers",
    "Sphere",
    "Task",
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
