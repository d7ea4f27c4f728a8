"""Training configuration: one typed dataclass, per-environment defaults, the paper's settings.

A `TrainConfig` is saved as ``config.json`` in every run directory and loaded back
to evaluate or resume. `default_config` gives the per-environment defaults shipped
with the toolkit (chosen to reach the issue's bars on a 2-core CPU);
`paper_config` gives the settings of the paper's appendix B.1, and
`beyond_paper` lists every field where a config departs from them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import finsler
from finsler.errors import InputError
from learn.midpoint.losses import actor_loss_of, derivative_terms, describe
from learn.run_config import (
    RunConfig,
    build_metric,
    check_choice,
    check_hidden,
    check_run_metric,
    ensure_registered,
    metric_class_path,
    metric_info,
    package_versions,
    resolve_metric,
    run_header,
    training_settings,
)

__all__ = [
    "METHODS",
    "MetricConfig",
    "RunConfig",
    "TrainConfig",
    "beyond_paper",
    "build_metric",
    "check_run_metric",
    "default_config",
    "ensure_registered",
    "metric_class_path",
    "metric_info",
    "model_free_overrides",
    "package_versions",
    "paper_config",
    "resolve_metric",
    "run_document",
    "run_header",
]

#: Actor-loss variants: eq. (6), eq. (17), eq. (18).
METHODS = ("midpoint", "inter", "two-to-one")
_TARGETS = ("mc", "td")
_SCHEDULES = ("paper", "full")
_LR_SCHEDULES = ("constant", "linear", "cosine")
_TRANSFORMS = ("none", "log1p", "relative")
_ACTIVATIONS = ("relu", "tanh")
_ENERGY_SCALES = ("none", "straight")
_ENERGY_SCHEDULES = ("constant", "lr")

#: The base of the method configs, `learn.run_config.RunConfig` (which holds the run's
#: metric and every run field); kept as a name.
MetricConfig = RunConfig


@dataclass
class TrainConfig(RunConfig):
    """Every setting of one training run of Algorithm 1 (saved as ``config.json``): the
    run fields of `learn.run_config.RunConfig` (``method``: the actor loss,
    ``midpoint`` (eq. 6), ``inter`` (eq. 17) or ``two-to-one`` (eq. 18); ``timesteps``:
    the budget T of evaluations of C, all-inclusive: the collected trees (the paper's
    timesteps) and every evaluation an extra actor term makes, in every epoch; also the
    horizon of the learning-rate schedule and of the paper's depth schedule; the
    evaluations of the validation set that select checkpoints are not counted;
    ``eval_every``: collections between evaluations), then the learner's own."""

    config_methods: ClassVar[tuple[str, ...]] = METHODS
    # eval_pairs 500: at 93 % success the binomial standard deviation of the success rate
    # is 1.1 points on 500 pairs (2.6 on 100, where the best of 20 evaluations is chosen
    # mostly by noise).
    run_defaults: ClassVar[Mapping[str, Any]] = {"eval_every": 50, "eval_pairs": 500}

    actor_loss_power: float = 2.0
    """Beyond the paper, model-free (the critic's values only): ``p`` of the midpoint loss
    ``2**(1 - 2/p) (|V(s, m)|**p + |V(m, g)|**p)**(2/p)``; ``p = 2`` is eq. (6) itself.
    Every ``p > 1`` has eq. (6)'s minimiser for an exact critic (the geodesic midpoint:
    both halves ``d/2``, the loss ``d**2 / 2``), but a larger ``p`` makes an uneven split
    cost more against a longer route, so critic and actor errors end in better-balanced
    halves (success bounds the largest segment). ``method="midpoint"`` only."""
    select_eps: float | None = None
    """Beyond the paper (None = off): the best checkpoint is the one with the highest
    validation success at this tighter tolerance (then at ``eps``, then the lowest mean
    largest segment cost), logged as ``success_rate_select``. Where success at ``eps`` is
    saturated (Panda: 99-100% at eps 20 for every late checkpoint) the rule at ``eps``
    picks among near-ties; this one sees the tolerances that still differ. Fixed for a
    run (it decides which checkpoints are kept)."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of both MLPs (paper: 64, 64)."""
    critic_hidden: tuple[int, ...] | None = None
    """Beyond the paper: the critic's hidden layer sizes when they differ from ``hidden``
    (None: ``hidden``). Generation calls only the actor, so a larger critic costs training
    time, not generation time. Measured on Matsumoto (128-128, 1e8, 2 seeds): no gain on
    fresh pairs for 1.5x the wall time
    (benchmarks/results/training/relative-critic-moved.md)."""
    activation: str = "relu"
    """``relu`` (paper) or ``tanh``."""
    lr: float = 3e-5
    """Adam learning rate of actor and critic (paper: 3e-5 Matsumoto, 1e-6 car-like and Panda)."""
    lr_schedule: str = "constant"
    """``constant`` (paper), ``linear`` or ``cosine`` decay over ``timesteps``."""
    lr_final_fraction: float = 0.05
    """Final learning rate as a fraction of ``lr`` for the decaying schedules."""
    minibatch_size: int = 256
    """Pairs per minibatch update (paper: 256)."""
    collection_size: int = 256
    """Collected pairs per iteration (trees are added until this many pairs are collected,
    counting the zero pairs when ``zero_pairs``); paper: one minibatch."""
    epochs: int = 10
    """Passes over each collection (paper N_epochs = 10); >1 reuses collected trees."""
    depth_schedule: str = "paper"
    """``paper``: depth floor(c / c_d) of appendix B.1 (c counts trees); ``full``: D_max."""
    targets: str = "mc"
    """``mc``: Monte-Carlo sums of leaf costs (Alg. 1); ``td``: TD(lambda) of eq. (8)."""
    td_lambda: float = 0.95
    """lambda of eq. (8) (used when ``targets == "td"``)."""
    critic_transform: str = "none"
    """Critic regresses ``none``: c, or ``log1p``: log(1 + c) (distance = expm1(output)),
    or, beyond the paper, ``relative``: log(c / r) from the pair's centre, direction and
    coordinate length r (distance = r * exp(output), the same relative precision at every
    level of the tree; zero pairs are exact and carry no target)."""
    zero_pairs: bool = True
    """Include the pairs (p, p, 0) of every tree point in the data (Alg. 1 does)."""
    normalize_inputs: bool = False
    """Scale coordinates to [-1, 1] by the domain's bounds before the networks."""
    actor_residual: bool = False
    """Actor mean = (s + g) / 2 + network output (scaled) instead of the raw output."""
    actor_relative: bool = False
    """Actor sees (centre, unit direction, length r) of the pair and predicts its offset
    from the coordinate midpoint and its std as multiples of r (a residual mean)."""
    actor_heads: int = 1
    """Beyond the paper: the actor predicts this many candidate midpoints per pair (each
    its own Gaussian) and a score per candidate; the policy is the best-scored one (one
    forward pass, so generation still makes 2**D - 1 predictions). In training every
    candidate descends the actor loss on its own and the scores learn which candidate the
    critic rates best (cross-entropy, weight ``actor_head_weight``): two routes around an
    obstacle are two candidates, not one average of them. Values of C only."""
    actor_head_weight: float = 0.1
    """Weight of the candidates' score loss (used when ``actor_heads > 1``)."""
    actor_head_share: float = 1.0
    """Weight of the actor loss of the heads the critic does not rate best, relative to
    the best one's (1: every head descends on its own; below 1: relaxed winner-take-all,
    the losing heads stay where they are as alternatives)."""
    actor_pairs: int = 0
    """Beyond the paper (0 = off): per actor step, this many fresh uniform pairs (the
    distribution of the trees' top level) join the minibatch of the actor loss. The
    collected data holds one top-level pair per tree beside 2**D - 1 shorter sub-pairs and
    2**D + 1 zero pairs, so the actor's long pairs, where the route and the bend are
    chosen, are rare. The actor loss needs the critic only, so these pairs cost no
    evaluation of C (values only, model-free)."""
    polish_steps: int = 0
    """Beyond the paper (0 = off): after the budget of evaluations of C is spent, this many
    actor steps against the frozen critic (the method's actor loss at the deterministic
    midpoints, Adam at ``polish_lr``), each on the sub-pairs of the policy's own
    deterministic trees between ``polish_pairs`` fresh pairs: the pairs generation meets,
    without the sampling noise of the collected trees. The critic only, so no evaluation
    of C (values only, model-free); validated every ``polish_eval_every`` steps, and the
    best checkpoint is chosen over the whole run as usual. A finished run resumed with
    polish settings polishes as a new run with them would."""
    polish_lr: float = 1e-4
    """Learning rate of the polish (a fresh Adam)."""
    polish_pairs: int = 64
    """Pairs per polish step (each gives its tree's 2**D - 1 sub-pairs)."""
    polish_eval_every: int = 250
    """Polish steps between two validation rows (and checkpoints)."""
    symmetric_critic: bool = False
    """For reversible metrics: V(s, g) = (net(s, g) + net(g, s)) / 2 exactly."""
    log_std_min: float = -20.0
    """Lower clamp of the actor's log standard deviation."""
    log_std_max: float = 2.0
    """Upper clamp of the actor's log standard deviation."""
    init_log_std: float | None = None
    """If set, the actor's log-std head starts near this value (bias = value, weights
    scaled by 0.01); None keeps PyTorch's default initialisation (log-std ~ 0)."""
    explore_std: float = 0.0
    """Beyond the paper: floor of the actor's standard deviation as a fraction of the
    coordinate distance ``|g - s|`` of the pair (0 = none). Without it the learned
    standard deviation collapses to ``exp(log_std_min)`` and the stochastic trees stop
    exploring other routes."""
    fused_adam: bool = False
    """Use PyTorch's fused Adam kernel (same update rule, fewer kernel launches; the
    floating-point results differ from the default implementation in the last bits)."""
    path_energy_weight: float = 0.0
    """Beyond the paper, and NOT model-free (it differentiates C): weight of an extra actor
    term, the discrete energy ``n * sum_i C(x_i, x_i+1)**2`` of the actor's own
    deterministic depth-D path between fresh pairs, differentiated through every level of
    the tree with the lowered torch ``cost`` (0 = off). The energy is smallest for a
    shortest path with equal segment costs, i.e. exactly the recursive geodesic
    midpoints."""
    path_energy_pairs: int = 256
    """Pairs (whole trees) per path-energy step; one step per epoch."""
    path_energy_scale: str = "none"
    """How the path-energy term is scaled per pair: ``none`` (the energy as it is) or
    ``straight`` (divided by the energy of the straight coordinate path between the same
    pair, a constant: scale-free, about 1 for every pair and metric; for metrics whose
    energies are 1e5-1e6, e.g. Panda, where the plain term swamps the critic's)."""
    path_energy_power: float = 2.0
    """``p`` of the path-energy term: ``(n**(p-1) sum_i C_i**p)**(2/p)``, the squared length
    for equal segment costs whatever ``p``; ``p = 2`` is the plain energy, a larger ``p``
    weights the costliest segments (those that decide success) more."""
    path_energy_schedule: str = "constant"
    """``constant`` or ``lr``: the path-energy weight multiplied by the learning-rate
    factor of ``lr_schedule`` (decays with it)."""
    route_candidates: int = 0
    """Beyond the paper (0 = off): per collection, for ``route_pairs`` fresh uniform pairs,
    try this many uniform candidate midpoints ``m`` and stitch the actor's deterministic
    depth-(D-1) paths ``s -> m -> g``; where a stitched path is at least 1% cheaper (true
    cost) than the actor's own path, the actor's mean at ``(s, g)`` is pulled towards that
    ``m`` in every actor step of the collection (weight ``route_weight``). Escapes routes
    that are only locally shortest; every target is the cost of a real path."""
    route_pairs: int = 64
    """Pairs searched per collection when ``route_candidates > 0``."""
    route_weight: float = 1.0
    """Weight of the squared distance of the actor's mean to a better route's midpoint."""
    # -- expert iteration (learn.midpoint.expert): the policy learns what the route search finds --
    expert_weight: float = 0.0
    """Beyond the paper, model-free (values of C only; 0 = off): weight of the actor's
    imitation of the route search's paths (``learn.midpoint.expert.SearchImitation``): every
    ``expert_every`` collections ``expert_pairs`` fresh pairs are searched from the
    policy's own paths; the searched paths' tree midpoints are the actor's targets, their
    sub-path costs the critic's (every evaluation of C the search makes is counted)."""
    expert_pairs: int = 64
    """Pairs searched per expert-iteration round."""
    expert_every: int = 1
    """Collections between expert-iteration rounds."""
    expert_search: str = "local"
    """The teacher: ``local`` (the route search's windows and equalizing rounds only) or
    ``full`` (the whole route search, ``learn.SearchSpec()``)."""
    expert_levels: int = 0
    """Top levels of the searched paths' midpoint trees used as actor targets (0: all)."""
    expert_keep: int = 4
    """Rounds of targets kept (a replay buffer)."""
    expert_critic: bool = True
    """Add the searched sub-paths' costs to the critic's data."""
    # ------------------------------------------------------------------------------------
    def validate(self) -> None:
        """Raise `finsler.InputError` naming the first impossible option of the
        learner (the run fields are [`RunConfig`][learn.RunConfig]'s to check)."""
        check_choice("targets", self.targets, _TARGETS)
        check_choice("depth_schedule", self.depth_schedule, _SCHEDULES)
        check_choice("lr_schedule", self.lr_schedule, _LR_SCHEDULES)
        check_choice("critic_transform", self.critic_transform, _TRANSFORMS)
        check_choice("activation", self.activation, _ACTIVATIONS)
        check_choice("path_energy_scale", self.path_energy_scale, _ENERGY_SCALES)
        check_choice("path_energy_schedule", self.path_energy_schedule, _ENERGY_SCHEDULES)
        if not (isinstance(self.path_energy_power, (int, float)) and not isinstance(
                self.path_energy_power, bool) and 1 < self.path_energy_power <= 64):
            raise InputError(f"path_energy_power must be a number in (1, 64], got "
                             f"{self.path_energy_power!r}")
        p = self.actor_loss_power
        if not (isinstance(p, (int, float)) and not isinstance(p, bool) and 1 < p <= 64):
            raise InputError(f"actor_loss_power must be a number in (1, 64], got {p!r}")
        actor_loss_of(self.method, p)  # the power applies to method 'midpoint' only
        for name in ("minibatch_size", "collection_size", "epochs", "path_energy_pairs",
                     "route_pairs", "expert_pairs", "expert_every", "expert_keep"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        check_hidden(self.hidden)
        if self.critic_hidden is not None:
            check_hidden(self.critic_hidden, name="critic_hidden")
        if not (self.lr > 0 and self.lr < 1):
            raise InputError(f"lr must be in (0, 1), got {self.lr!r}")
        if not (0 < self.lr_final_fraction <= 1):
            raise InputError(f"lr_final_fraction must be in (0, 1], got {self.lr_final_fraction}")
        if isinstance(self.route_candidates, int) and self.route_candidates < 0:
            raise InputError(f"route_candidates must be >= 0, got {self.route_candidates!r}")
        if not (0.0 <= self.route_weight < float("inf")):
            raise InputError(f"route_weight must be finite and >= 0, got {self.route_weight!r}")
        if not (0.0 <= self.explore_std < float("inf")):
            raise InputError(f"explore_std must be finite and >= 0, got {self.explore_std!r}")
        if not isinstance(self.actor_heads, int) or isinstance(
                self.actor_heads, bool) or not 1 <= self.actor_heads <= 64:
            raise InputError(f"actor_heads must be an integer in [1, 64], got "
                             f"{self.actor_heads!r}")
        if not (0.0 <= self.actor_head_weight < float("inf")):
            raise InputError(f"actor_head_weight must be finite and >= 0, got "
                             f"{self.actor_head_weight!r}")
        if not isinstance(self.actor_pairs, int) or self.actor_pairs < 0:
            raise InputError(f"actor_pairs must be an integer >= 0, got {self.actor_pairs!r}")
        for name, low in (("polish_steps", 0), ("polish_pairs", 1), ("polish_eval_every", 1)):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, int) or val < low:
                raise InputError(f"{name} must be an integer >= {low}, got {val!r}")
        if self.select_eps is not None and (
                isinstance(self.select_eps, bool) or not isinstance(self.select_eps, (int, float))
                or not 0.0 < self.select_eps < float("inf")):
            raise InputError(f"select_eps must be None or positive and finite, got "
                             f"{self.select_eps!r}")
        if not (0.0 < self.polish_lr < float("inf")):
            raise InputError(f"polish_lr must be positive and finite, got {self.polish_lr!r}")
        if not (0.0 <= self.actor_head_share <= 1.0):
            raise InputError(f"actor_head_share must be in [0, 1], got "
                             f"{self.actor_head_share!r}")
        check_choice("expert_search", self.expert_search, ("local", "full"))
        if not (0.0 <= self.expert_weight < float("inf")):
            raise InputError(f"expert_weight must be finite and >= 0, got "
                             f"{self.expert_weight!r}")
        if not isinstance(self.expert_levels, int) or isinstance(
                self.expert_levels, bool) or self.expert_levels < 0:
            raise InputError(f"expert_levels must be an integer >= 0, got "
                             f"{self.expert_levels!r}")
        if not (0.0 <= self.path_energy_weight < float("inf")):
            raise InputError("path_energy_weight must be finite and >= 0, got "
                             f"{self.path_energy_weight!r}")
        if not (0.0 <= self.td_lambda <= 1.0):
            raise InputError(f"td_lambda must be in [0, 1], got {self.td_lambda!r}")
        if not self.log_std_min < self.log_std_max:
            raise InputError("log_std_min must be below log_std_max")
        if self.symmetric_critic and not self.metric.reversible:
            raise InputError(
                f"symmetric_critic needs a reversible metric; {self.env!r} is not reversible"
            )

    # ------------------------------------------------------------------------------------
    @property
    def model_free(self) -> bool:
        """True if training uses values of C only (like the paper); False if a term
        differentiates C (see `learn.midpoint.losses`)."""
        return not derivative_terms(self)


# ----------------------------------------------------------------------------------------
# The paper's settings and ours
# ----------------------------------------------------------------------------------------
def paper_config(env: str, **overrides: Any) -> TrainConfig:
    """The settings of appendix B.1 for ``env`` (the metric's ``training.paper_lr`` and
    ``paper_timesteps``; metrics that declare none: the Matsumoto ones)."""
    paper = training_settings(env)
    base = TrainConfig(
        env=env,
        lr=paper.paper_lr,
        timesteps=paper.paper_timesteps,
    )
    return base.replace(**overrides) if overrides else base


# Beyond the paper (`benchmarks/learn_ablation.py` measures them): full depth from the
# start, big collections and minibatches with few epochs (vectorised trees), a higher
# learning rate with cosine decay, log1p critic targets, inputs scaled to [-1, 1] and a
# residual actor mean around the coordinate midpoint; the per-metric settings on top of
# these (car-like's path-energy term with one pass per collection, the relative actor and
# critic) are each metric's `Metric.training.defaults`.
_OURS_COMMON: dict[str, Any] = dict(
    depth_schedule="full",
    critic_transform="log1p",
    normalize_inputs=True,
    actor_residual=True,
    lr=1e-3,
    lr_schedule="cosine",
    lr_final_fraction=0.05,
    collection_size=16384,
    minibatch_size=1024,
    epochs=3,
    log_std_min=-10.0,
    log_std_max=1.0,
)


def default_config(env: str, **overrides: Any) -> TrainConfig:
    """The toolkit's documented defaults for ``env`` (the settings of the shipped policies);
    ``overrides`` replace fields. Unknown environments get the common settings."""
    ensure_registered(env, overrides.get("metric_class"))
    # the metric's measured defaults (Metric.training.defaults, with their figures beside
    # them in finsler/metrics/paper.py) over the common ones
    settings = {**_OURS_COMMON, **training_settings(env).defaults}
    settings.update(overrides)
    return TrainConfig(env=env, **settings)


# The model-free defaults (values of C only): the path-energy term off, and the number of
# passes over each collection that Algorithm 1 alone learns best with (one pass suits the
# defaults only because the energy term supplies the local signal). They keep the
# defaults' relative actor, which learns faster and finds shorter paths than the absolute
# one (benchmarks/results/training/actor-relative-moved.md). `Metric.training.model_free` holds the
# per-metric settings.


def model_free_overrides(env: str) -> dict[str, Any]:
    """Settings that turn the defaults of ``env`` into the model-free defaults: every term
    differentiating C (``learn.midpoint.losses``) off, plus the settings Algorithm 1 alone is
    measured best with."""
    return {"path_energy_weight": 0.0, **training_settings(env).model_free}


def beyond_paper(cfg: TrainConfig) -> dict[str, dict[str, Any]]:
    """Fields where ``cfg`` departs from the paper's settings: ``{field: {used, paper}}``
    (run-control fields such as seed, device, minutes and evaluation cadence excluded)."""
    ref = paper_config(cfg.env).to_dict()
    skip = {"seed", "device", "threads", "minutes", "eval_every", "eval_pairs", "env",
            "metric_params", "metric_class", "method", "depth", "eps", "timesteps"}
    out = {}
    for k, v in cfg.to_dict().items():
        if k not in skip and ref[k] != v:
            out[k] = {"used": v, "paper": ref[k]}
    return out


def run_document(cfg: TrainConfig) -> dict[str, Any]:
    """``config.json``'s sections about the midpoint learner: loss, terms, model-free or
    not, what the counts mean, how the best checkpoint is chosen, versions, and the list
    of choices beyond the paper."""
    return {
        **describe(cfg),
        "counts": "timesteps = every evaluation of C made to learn (all-inclusive: trees "
                  "and every extra term, in every epoch; the validation evaluations that "
                  "select checkpoints are not counted); "
                  "timesteps_paper = evaluations in collected trees (the paper's count); "
                  "timesteps_derivative = evaluations whose derivative was used",
        "selection": f"checkpoint_best by success on finsler.validation_pairs (seed "
                     f"{finsler.VALIDATION_SEED}, {cfg.eval_pairs} pairs)"
                     + (f", first at select_eps = {cfg.select_eps}, then at eps"
                        if cfg.select_eps is not None else ""),
        "versions": package_versions(),
        "beyond_paper": beyond_paper(cfg),
    }


def config_json(cfg: TrainConfig) -> str:
    """The ``config.json`` text of a run: the config, metric, task, versions and the list of
    choices beyond the paper."""
    return json.dumps({**run_header(cfg), **run_document(cfg)}, indent=2)
