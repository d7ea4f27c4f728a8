"""The contract of an extra actor term of the midpoint learner (`learn.midpoint.losses`,
`learn.midpoint.expert`): what it reads of the trainer and what one actor step returns."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np
import torch

import finsler
from learn.midpoint.networks import Actor

__all__ = ["ActorTerm", "TermOutput", "Trainer"]


class Trainer(Protocol):
    """What a term reads of the trainer running it (`learn.Trainer`)."""

    actor: Actor
    metric: finsler.Metric
    np_rng: np.random.Generator
    gen: torch.Generator
    device: torch.device
    dim: int
    depth_max: int
    cfg: Any
    lr: float
    """The learning rate of the current iteration (``cfg.lr`` times the schedule's factor)."""


@dataclass
class TermOutput:
    """One actor step's contribution of a term: its weighted loss and the evaluations of
    C it made (``derivative``: how many of them were differentiated)."""

    loss: torch.Tensor | None
    evaluations: int = 0
    derivative: int = 0


class ActorTerm:
    """An extra actor term: `prepare` runs once per collection, `step` once
    per actor step; both return the evaluations of C they made. A term may also give the
    critic data of its own (`critic_data`) and keep state across collections
    (`state` / `load`, saved in the checkpoints so that a resumed run replays
    the same steps)."""

    name: ClassVar[str] = ""
    uses_derivative_of_C: ClassVar[bool] = False

    def prepare(self, trainer: Trainer) -> int:
        """Work done once per collection (before its updates); returns C evaluations."""
        return 0

    def step(self, trainer: Trainer) -> TermOutput:
        raise NotImplementedError

    def critic_data(self, trainer: Trainer) -> tuple[torch.Tensor, ...] | None:
        """Extra (starts, goals, costs) float64 for this collection's updates, or None."""
        return None

    def state(self) -> dict[str, Any] | None:
        """State to keep in checkpoints (None: stateless)."""
        return None

    def load(self, st: dict[str, Any], device: Any) -> None:
        """Restore `state`."""
