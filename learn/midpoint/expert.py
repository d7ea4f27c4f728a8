"""Expert iteration: the policy learns what the route search finds (beyond the paper).

Every searched path of `learn.midpoint.search.search_paths` is a better answer than the
policy's own, found with values of C only: a free teacher. `SearchImitation` is an
actor term (`learn.midpoint.term.ActorTerm`) that, every ``every`` collections, draws
``pairs`` fresh uniform pairs, lets the search (with the policy's current deterministic
midpoints as its generator) improve the policy's paths between them, and turns each searched
path ``P`` (``2**D + 1`` points) into training data for both networks:

* **actor targets**: for every node of the path's midpoint tree, the sub-pair
  ``(P[i w], P[(i + 1) w])`` and its midpoint ``P[i w + w / 2]`` (``w = 2**(D - l)`` at
  level ``l``): ``2**D - 1`` triples per path. Each actor step adds
  ``weight * mean |mu(a, b) - m|**2 / |b - a|**2`` over a minibatch of them (the policy's
  deterministic mean pulled to the searched midpoint, relative to the sub-pair's size so
  that every level counts alike);
* **critic targets**: the same sub-pairs with the cost of the searched path between their
  ends (the sum of its segment costs: the cost of a real path, an upper bound of the
  distance, lower than the policy's own), added to the collection the critic regresses on.

The targets of the last ``keep`` searches are kept (a small replay buffer). The search
evaluates C (values only) and the actor; every evaluation is counted in ``timesteps``. No
derivative of C is taken: the term is model-free.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import torch

import finsler
from learn.midpoint.networks import predictor
from learn.midpoint.search import SearchSpec, search_paths
from learn.midpoint.term import ActorTerm, TermOutput, Trainer

__all__ = ["SearchImitation", "search_spec", "tree_targets"]


def tree_targets(paths: torch.Tensor, costs: torch.Tensor, levels: int | None = None
                 ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Midpoint-tree triples of paths ``(K, 2**D + 1, dim)`` with segment costs
    ``(K, 2**D)``: sub-pair starts ``a``, ends ``b``, midpoints ``m`` (each ``(N, dim)``)
    and the path's cost between ``a`` and ``b`` ``(N,)``, for the top ``levels`` levels
    (default all ``D``; level 0 is the whole pair)."""
    n1, dim = paths.shape[1], paths.shape[2]
    n = n1 - 1
    depth = n.bit_length() - 1
    if 2**depth != n:
        raise ValueError(f"paths must have 2**D + 1 points, got {n1}")
    use = depth if levels is None else min(levels, depth)
    cum = torch.cat([torch.zeros_like(costs[:, :1]), torch.cumsum(costs, 1)], 1)
    a, b, m, c = [], [], [], []
    for lev in range(use):
        w = n >> lev
        lo = torch.arange(0, n, w, device=paths.device)
        a.append(paths[:, lo].reshape(-1, dim))
        b.append(paths[:, lo + w].reshape(-1, dim))
        m.append(paths[:, lo + w // 2].reshape(-1, dim))
        c.append((cum[:, lo + w] - cum[:, lo]).reshape(-1))
    return torch.cat(a), torch.cat(b), torch.cat(m), torch.cat(c)


@dataclass
class SearchImitation(ActorTerm):
    """The expert-iteration term (module docstring). ``weight`` of the actor's imitation
    loss; ``pairs`` searched every ``every`` collections with ``spec``; targets of the top
    ``levels`` tree levels (0: all); ``keep`` searches kept; ``critic``: add the searched
    sub-paths' costs to the critic's data."""

    weight: float
    pairs: int
    every: int
    spec: SearchSpec
    levels: int = 0
    keep: int = 4
    critic: bool = True
    name: ClassVar[str] = "search_imitation"
    uses_derivative_of_C: ClassVar[bool] = False
    buffer: list[tuple[torch.Tensor, ...]] = field(default_factory=list)
    calls: int = 0

    def prepare(self, trainer: Trainer) -> int:
        self.calls += 1
        if (self.calls - 1) % self.every:
            return 0
        k, depth = self.pairs, trainer.depth_max
        ends = finsler.sample_pairs(trainer.metric, k, trainer.np_rng)
        e = torch.as_tensor(ends, dtype=torch.float64, device=trainer.device)
        actor = trainer.actor
        was_training = actor.training
        actor.eval()
        try:
            found = search_paths(trainer.metric, predictor(actor, trainer.metric),
                                 e[:, 0], e[:, 1], depth,
                                 float(trainer.cfg.eval_eps), self.spec)
        finally:
            actor.train(was_training)
        paths = torch.as_tensor(found.paths, dtype=torch.float64, device=trainer.device)
        costs = trainer.metric.path_costs(paths)
        a, b, m, c = tree_targets(paths, costs, self.levels or None)
        self.buffer = [*self.buffer, (a.float(), b.float(), m.float(), c)][-self.keep:]
        return found.evaluations + k * 2**depth

    def _targets(self) -> tuple[torch.Tensor, ...] | None:
        if not self.buffer:
            return None
        return tuple(torch.cat(parts) for parts in zip(*self.buffer, strict=True))

    def critic_data(self, trainer: Trainer) -> tuple[torch.Tensor, ...] | None:
        """(starts, goals, costs) float64 of the searched sub-paths for the critic, or
        ``None``."""
        t = self._targets()
        if not self.critic or t is None:
            return None
        a, b, _, c = t
        return a.double(), b.double(), c

    def step(self, trainer: Trainer) -> TermOutput:
        t = self._targets()
        if t is None or self.weight == 0:
            return TermOutput(None)
        a, b, m, _ = t
        size = min(a.shape[0], trainer.cfg.minibatch_size)
        idx = torch.randint(0, a.shape[0], (size,), generator=trainer.gen,
                            device=a.device)
        mean = trainer.actor.distribution(a[idx], b[idx])[0]
        scale = ((b[idx] - a[idx]) ** 2).sum(-1).clamp_min(1e-12)
        loss = (((mean - m[idx]) ** 2).sum(-1) / scale).mean()
        return TermOutput(self.weight * loss)

    def state(self) -> dict[str, Any]:
        """What a checkpoint keeps of the term (its buffer and call count)."""
        return {"calls": self.calls, "buffer": [tuple(x.cpu() for x in item)
                                                for item in self.buffer]}

    def load(self, st: dict[str, Any], device: Any) -> None:
        self.calls = int(st["calls"])
        self.buffer = [tuple(x.to(device) for x in item) for item in st["buffer"]]


def search_spec(kind: str) -> SearchSpec:
    """The search used as the teacher: ``full`` (`SearchSpec` defaults) or ``local``
    (windows and equalizing only: ~13x fewer evaluations of C on Matsumoto)."""
    if kind == "local":
        return SearchSpec(levels=0, polish=0)
    return SearchSpec()
