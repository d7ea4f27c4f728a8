"""The midpoint learner's losses and extra terms as small named objects.

`learn.Trainer` reads as Algorithm 1: a critic step of eq. (5), an actor step of
the `ActorLoss` chosen by ``TrainConfig.method`` (eq. 6, 17 or 18), plus a list of
named `ActorTerm` objects added to the actor's loss. Each term states whether it
differentiates C (not model-free: the paper's method uses values of C only) and returns
the number of evaluations of C it made, so that the trainer's ``timesteps`` count every
evaluation whatever it is for.

The paper's baselines live beside this learner, in `learn.seq.trainer` and `learn.pg.trainer`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import torch

import finsler
from finsler.errors import InputError
from learn.midpoint.expert import SearchImitation, search_spec
from learn.midpoint.term import ActorTerm, TermOutput, Trainer
from learn.tree import build_tree


class TrainConfig(Protocol):
    """The fields of [`learn.TrainConfig`][learn.TrainConfig] that choose the loss and the terms."""

    method: str
    actor_loss_power: float
    path_energy_weight: float
    path_energy_pairs: int
    path_energy_scale: str
    path_energy_power: float
    path_energy_schedule: str
    route_candidates: int
    route_pairs: int
    route_weight: float
    expert_weight: float
    expert_pairs: int
    expert_every: int
    expert_search: str
    expert_levels: int
    expert_keep: int
    expert_critic: bool


__all__ = [
    "ACTOR_LOSSES",
    "ActorLoss",
    "ActorTerm",
    "PathEnergy",
    "RouteSearch",
    "TermOutput",
    "actor_loss_of",
    "actor_terms",
    "derivative_terms",
    "describe",
]


@dataclass(frozen=True)
class ActorLoss:
    """Per-pair actor loss from ``V(s, m)`` and ``V(m, g)`` ``(N,)`` (critic held fixed)."""

    name: str
    equation: str
    fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor]

    def __call__(self, v_first: torch.Tensor, v_second: torch.Tensor) -> torch.Tensor:
        return self.fn(v_first, v_second)


#: eq. (6) midpoints, eq. (17) intermediate points, eq. (18) 2:1 points.
ACTOR_LOSSES: dict[str, ActorLoss] = {
    "midpoint": ActorLoss("midpoint", "eq. (6)", lambda a, b: a**2 + b**2),
    "inter": ActorLoss("inter", "eq. (17)", lambda a, b: a + b),
    "two-to-one": ActorLoss("two-to-one", "eq. (18)", lambda a, b: a**2 + 2.0 * b**2),
}


def _path_costs_safe(metric: Any, pts: torch.Tensor) -> torch.Tensor:
    """``metric.path_costs(pts)`` ``(K, n)`` whose gradient is finite where two consecutive
    points coincide: C is 0 there, but its derivative is 0/0 for the usual
    ``F = sqrt(...)`` (the projection into the domain maps neighbouring midpoints onto the
    same boundary point late in training; one such NaN gradient destroyed a 4e8-evaluation
    car-like run). Those segments are evaluated at a displaced end, detached, and masked to
    0; every other segment is computed exactly as before."""
    a, b = pts[:, :-1], pts[:, 1:]
    same = (a == b).all(-1, keepdim=True)  # (K, n, 1)
    if not bool(same.any()):
        return metric.path_costs(pts)
    offset = torch.zeros_like(a[:1, :1])
    offset[..., 0] = 1e-6
    b = torch.where(same, (a + offset).detach(), b)
    k, n, dim = a.shape
    c = metric.cost(a.reshape(-1, dim), b.reshape(-1, dim)).reshape(k, n)
    return torch.where(same[..., 0], torch.zeros_like(c), c)


def _p_energy(c: torch.Tensor, p: float) -> torch.Tensor:
    """``(n**(p-1) sum_i c_i**p)**(2/p)`` per row of ``c`` ``(K, n)``; ``n sum c**2`` for
    ``p = 2`` (computed so, bit for bit). For ``p > 2`` the sum is taken relative to the
    row's largest cost (no overflow, and no 0/0 in the gradient of a zero row)."""
    n = c.shape[1]
    if p == 2:
        return n * (c**2).sum(1)
    top = c.detach().amax(1, keepdim=True).clamp_min(1e-300)
    r = (c / top) ** p
    return (n ** (p - 1) * r.sum(1)).clamp_min(1e-300) ** (2.0 / p) * top[:, 0] ** 2


@dataclass
class PathEnergy(ActorTerm):
    """Beyond the paper: ``weight * n * sum_i C(x_i, x_i+1)**2`` (with ``power`` p: the
    p-energy of `_p_energy`), the discrete energy of the actor's own deterministic
    depth-D path between ``pairs`` fresh uniform pairs,
    differentiated through every level of the tree with the lowered torch cost (float64).
    Smallest for a shortest path with equal segment costs: the recursive geodesic midpoints.
    Uses the derivative of C (``pairs * 2**D`` evaluations per actor step)."""

    weight: float
    pairs: int
    scale: str = "none"
    """``none`` or ``straight``: each pair's energy divided by that of the straight
    coordinate path between its ends (a constant; ``pairs * 2**D`` more evaluations of C,
    values only)."""
    power: float = 2.0
    """``p``: the energy is ``(n**(p-1) sum_i C_i**p)**(2/p)`` (``p = 2``: the plain
    energy ``n sum C_i**2``). Equal to the squared length for equal segment costs, so
    every ``p > 1`` has the same minimisers, but a larger ``p`` weights the costliest
    segments more (``p -> inf``: the squared largest segment times ``n**2``)."""
    schedule: str = "constant"
    """``constant`` or ``lr``: the weight multiplied by the run's learning-rate factor
    (``lr / cfg.lr``), so that it decays with the learning rate."""
    name: ClassVar[str] = "path_energy"
    uses_derivative_of_C: ClassVar[bool] = True

    def energy(self, trainer: Trainer) -> torch.Tensor:
        """Energies ``(pairs,)`` of the actor's paths between fresh pairs drawn from the
        run's generator (scaled per `scale`), differentiable in the actor's
        parameters."""
        k, depth = self.pairs, trainer.depth_max
        ends = finsler.sample_pairs(trainer.metric, k, trainer.np_rng)
        e = torch.as_tensor(ends, dtype=torch.float32, device=trainer.device)
        pts = build_tree(e[:, 0], e[:, 1], depth,
                         lambda a, b: trainer.actor(a, b, deterministic=True)).double()
        c = _path_costs_safe(trainer.metric, pts)
        energy = _p_energy(c, self.power)
        if self.scale == "straight":
            with torch.no_grad():
                t = torch.linspace(0.0, 1.0, c.shape[1] + 1, dtype=torch.float64,
                                   device=pts.device)[None, :, None]
                e64 = e.double()
                line = e64[:, :1] + t * (e64[:, 1:] - e64[:, :1])
                cs = _path_costs_safe(trainer.metric, line)
                ref = _p_energy(cs, self.power).clamp_min(1e-300)
            energy = energy / ref
        return energy.float()

    def step(self, trainer: Trainer) -> TermOutput:
        n = self.pairs * 2**trainer.depth_max
        evals = 2 * n if self.scale == "straight" else n
        w = self.weight
        if self.schedule == "lr":
            w *= trainer.lr / trainer.cfg.lr
        return TermOutput(w * self.energy(trainer).mean(), evaluations=evals,
                          derivative=n)


@dataclass
class RouteSearch(ActorTerm):
    """Beyond the paper: per collection, for ``pairs`` fresh uniform pairs try
    ``candidates`` uniform midpoints ``m`` and stitch the actor's deterministic
    depth-(D-1) paths ``s -> m -> g``; where a stitched path costs at least 1% less (true
    cost) than the actor's own, pull the actor's mean at ``(s, g)`` towards that ``m``
    (squared distance, ``weight``) in every actor step of the collection. Values of C only:
    ``pairs * 2**D * (1 + candidates)`` evaluations per collection."""

    candidates: int
    pairs: int
    weight: float
    name: ClassVar[str] = "route_search"
    uses_derivative_of_C: ClassVar[bool] = False

    def __post_init__(self) -> None:
        self.target: tuple[torch.Tensor, torch.Tensor, torch.Tensor] | None = None

    def prepare(self, trainer: Trainer) -> int:
        k, n_c, dim, depth = self.pairs, self.candidates, trainer.dim, trainer.depth_max
        dom, rng, dev = trainer.metric.domain, trainer.np_rng, trainer.device
        e = torch.as_tensor(dom.sample(2 * k, rng).reshape(k, 2, dim), dtype=torch.float32,
                            device=dev)
        m = torch.as_tensor(dom.sample(k * n_c, rng), dtype=torch.float32, device=dev)
        s_rep = e[:, 0].repeat_interleave(n_c, 0)
        g_rep = e[:, 1].repeat_interleave(n_c, 0)

        def mean(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
            return trainer.actor(a, b, deterministic=True)

        def total(pts: torch.Tensor) -> torch.Tensor:
            return trainer.metric.path_costs(pts.double()).sum(1)

        with torch.no_grad():
            own = total(build_tree(e[:, 0], e[:, 1], depth, mean))
            alt = (total(build_tree(s_rep, m, depth - 1, mean))
                   + total(build_tree(m, g_rep, depth - 1, mean))).reshape(k, n_c)
            best, idx = alt.min(1)
        better = best < 0.99 * own
        self.target = None
        if bool(better.any()):
            m_best = m.reshape(k, n_c, dim)[torch.arange(k, device=dev), idx]
            self.target = (e[better, 0], e[better, 1], m_best[better])
        return k * 2**depth * (1 + n_c)

    def step(self, trainer: Trainer) -> TermOutput:
        if self.target is None:
            return TermOutput(None)
        s, g, m = self.target
        mean = trainer.actor.distribution(s, g)[0]
        return TermOutput(self.weight * ((mean - m) ** 2).sum(-1).mean())


def actor_terms(cfg: TrainConfig) -> list[ActorTerm]:
    """The extra actor terms a config switches on, in the order they are added."""
    terms: list[ActorTerm] = []
    if cfg.path_energy_weight > 0:
        terms.append(PathEnergy(cfg.path_energy_weight, cfg.path_energy_pairs,
                                cfg.path_energy_scale, cfg.path_energy_power,
                                cfg.path_energy_schedule))
    if cfg.route_candidates > 0:
        terms.append(RouteSearch(cfg.route_candidates, cfg.route_pairs, cfg.route_weight))
    if cfg.expert_weight > 0:  # expert iteration (learn.midpoint.expert): values of C only
        terms.append(SearchImitation(cfg.expert_weight, cfg.expert_pairs, cfg.expert_every,
                                     search_spec(cfg.expert_search), cfg.expert_levels,
                                     cfg.expert_keep, cfg.expert_critic))
    return terms


def _midpoint_power(p: float) -> ActorLoss:
    """Eq. (6) with power ``p``: ``2**(1 - 2/p) (|a|**p + |b|**p)**(2/p)`` (``a**2 + b**2``
    at ``p = 2``; equal to it, ``d**2 / 2``, wherever ``a = b = d / 2``)."""
    c = 2.0 ** (1.0 - 2.0 / p)

    def fn(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        # relative to the larger of the two: no overflow, and no 0/0 in the gradient
        top = torch.maximum(a.abs(), b.abs()).detach().clamp_min(1e-30)
        r = (a / top).abs() ** p + (b / top).abs() ** p  # in [1, 2] unless both are 0
        return c * r.clamp_min(torch.finfo(r.dtype).tiny) ** (2.0 / p) * top**2

    return ActorLoss("midpoint", f"eq. (6) with power p = {p:g}", fn)


def actor_loss_of(method: str, power: float = 2.0) -> ActorLoss:
    """The `ActorLoss` of a method name (``midpoint``, ``inter``, ``two-to-one``);
    ``power`` != 2 (``midpoint`` only): `_midpoint_power`."""
    if method not in ACTOR_LOSSES:
        raise InputError(f"unknown method {method!r}; known: {', '.join(ACTOR_LOSSES)}")
    if power == 2:
        return ACTOR_LOSSES[method]
    if method != "midpoint":
        raise InputError(f"actor_loss_power applies to method 'midpoint' only (eq. 6); "
                         f"method {method!r} needs actor_loss_power=2")
    return _midpoint_power(float(power))


def derivative_terms(cfg: TrainConfig) -> list[str]:
    """Names of the terms of ``cfg`` that differentiate C (empty = model-free)."""
    return [t.name for t in actor_terms(cfg) if t.uses_derivative_of_C]


def describe(cfg: TrainConfig) -> dict[str, Any]:
    """What ``config.json`` says about the method: loss, terms, model-free or not."""
    loss = actor_loss_of(cfg.method, cfg.actor_loss_power)
    uses = derivative_terms(cfg)
    return {
        "actor_loss": f"{loss.name} ({loss.equation})",
        "actor_terms": [t.name for t in actor_terms(cfg)],
        "model_free": not uses,
        "uses_derivative_of_C": uses,
    }
