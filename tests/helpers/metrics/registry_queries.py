"""The test metrics of ``tests/finsler/test_registry_queries.py``: Flat, FlatNoForm,
Trained."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

import finsler
from finsler import Box


@dataclass(frozen=True)
class Flat(finsler.Metric):
    """A user's 2-D metric with a closed form: Euclidean on a box."""

    name: ClassVar[str] = "test-flat-closed"

    @property
    def domain(self) -> Box:
        return Box((-1.0, -1.0), (1.0, 1.0))

    def F_sx(self, x, v):
        import casadi as ca
        return ca.sqrt(ca.dot(v, v))

    def distance(self, x, y):
        return np.linalg.norm(np.asarray(y) - np.asarray(x), axis=-1)


@dataclass(frozen=True)
class FlatNoForm(Flat):
    name: ClassVar[str] = "test-flat-open"

    # no closed form: the hook is not overridden
    distance = finsler.Metric.distance


@dataclass(frozen=True)
class Trained(Flat):
    """A user's metric declaring its own learning settings (data on the metric)."""

    name: ClassVar[str] = "test-flat-trained"
    training: ClassVar[finsler.TrainingSettings] = finsler.TrainingSettings(
        paper_lr=2e-4, paper_timesteps=123_456,
        defaults=dict(timesteps=777_000, collection_size=2048), model_free=dict(epochs=5))
