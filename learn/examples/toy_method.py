"""A learning method in one file: the straight-line midpoint plus a learned offset.

An example to copy for a method of your own (docs/guides/methods.md, "Adding a learning
method"); it uses public names of `learn` only. Import it with ``--method-module
learn.examples.toy_method`` (or a copy of this file with ``--method-module
path/to/my_method.py``); ``geodesics train --method toy``, ``evaluate --run`` and ``sweep
--methods toy`` then use it like a built-in method.

Policy: ``m(s, g) = (s + g) / 2 + |g - s| * MLP(s, g)``, projected into the domain; a path
is the tree of recursive midpoint insertion to the task's depth D (``2**D`` segments).
Training lowers the mean path length ``sum_i C(p_i, p_{i+1})`` of sampled pairs by random
search on the weights (values of C only: model-free); every evaluation of C made is
counted in ``timesteps``. The run fields (env, seed, budget, minutes, device, threads,
depth, eps, evaluation cadence) and their checks are `learn.run_config.RunConfig`'s;
the run directory, resume, budget, minutes, signals, metrics rows and checkpoints are the
run loop's ([`learn.loop.RunLoop`][learn.loop.RunLoop]).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import torch
from torch import nn
from torch.nn.utils import parameters_to_vector, vector_to_parameters

import finsler
from finsler.errors import InputError
from learn.base import LoadedPolicy
from learn.evaluation import check_pairs, evaluate_paths
from learn.loop import RunLoop, best_record, eval_columns, load_run, load_weights
from learn.registry import Method, register_method
from learn.run_config import RunConfig, check_hidden
from learn.tree import build_tree

__all__ = ["ToyConfig", "ToyPolicy", "ToyTrainer", "load_toy_policy", "offset_net",
           "toy_paths"]


@dataclass
class ToyConfig(RunConfig):
    """Every setting of a toy run (saved in the run's ``config.json``): RunConfig's run
    fields (env, metric_params, metric_class, method, seed, timesteps, minutes, device,
    threads, depth, eps, eval_every, eval_pairs), then the toy's own."""

    config_methods: ClassVar[tuple[str, ...]] = ("toy",)  # the values of ``method``
    # RunConfig's defaults that differ for the toy (a budget of evaluations of C, and
    # iterations between metrics rows); the fields themselves are never declared again
    run_defaults: ClassVar[Mapping[str, Any]] = {"timesteps": 20_000, "eval_every": 5}

    hidden: int = 16  # the toy's own settings: MLP width,
    batch: int = 32  # pairs per iteration,
    directions: int = 4  # random directions per iteration (2 batches of paths each),
    sigma: float = 0.02  # their scale,
    lr: float = 0.01  # and the step size

    def validate(self) -> None:
        """The toy's own checks (field types and the run fields are checked already)."""
        if self.device != "cpu":
            raise InputError(f"the toy method runs on the CPU only, got {self.device!r}")
        for name in ("batch", "directions"):
            if getattr(self, name) < 1:
                raise InputError(f"{name} must be positive, got {getattr(self, name)!r}")
        check_hidden((self.hidden,), self.metric.dim)  # positive, fits in memory
        if not (0 < self.sigma < 1 and 0 < self.lr < 1):
            raise InputError(f"sigma and lr must be in (0, 1), got {self.sigma}, {self.lr}")


def offset_net(dim: int, hidden: int) -> nn.Module:
    """The MLP ``(s, g)`` ``(N, 2 dim)`` -> offset ``(N, dim)``, float64."""
    return nn.Sequential(nn.Linear(2 * dim, hidden), nn.Tanh(),
                         nn.Linear(hidden, dim)).double()


def toy_paths(net: nn.Module, metric: finsler.Metric, s: torch.Tensor, g: torch.Tensor,
              depth: int) -> torch.Tensor:
    """Paths ``(K, 2**depth + 1, dim)`` from starts and goals ``(K, dim)``, float64."""
    def midpoint(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        gap = torch.linalg.vector_norm(b - a, dim=-1, keepdim=True)
        return metric.domain.project(0.5 * (a + b) + gap * net(torch.cat([a, b], -1)))

    return build_tree(s, g, depth, midpoint)


class ToyPolicy(LoadedPolicy):
    """A trained toy policy: ``generate``, ``midpoint`` and ``evaluate`` as the built-in
    policies (a `learn.MidpointPolicy`; ``config``, ``metric``, ``depth``, ``eps``,
    ``source``, ``checkpoint``: LoadedPolicy's)."""

    def __init__(self, net: nn.Module, config: ToyConfig, source: str = "",
                 checkpoint: str = "") -> None:
        super().__init__(config, source, checkpoint)
        self.net = net.eval()

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """``(K, dim)`` x2 -> paths ``(K, 2**D + 1, dim)`` (D: ``depth`` or the task's)."""
        s = torch.as_tensor(self.metric.domain.check(starts, "starts"), dtype=torch.float64)
        g = torch.as_tensor(self.metric.domain.check(goals, "goals"), dtype=torch.float64)
        if s.ndim != 2 or s.shape != g.shape:
            raise InputError(f"starts and goals must both be (K, dim), got {tuple(s.shape)}, "
                             f"{tuple(g.shape)}")
        with torch.no_grad():
            return toy_paths(self.net, self.metric, s, g, self.check_depth(depth)).numpy()

    def midpoint(self, starts: Any, goals: Any) -> np.ndarray:
        """Predicted midpoints ``(K, dim)``."""
        return self.generate(starts, goals, depth=1)[:, 1]

    def evaluate(self, pairs: Any = None, eps: float | None = None,
                 depth: int | None = None) -> Any:
        """Section 5.1 evaluation on ``pairs`` ``(K, 2, dim)`` (default: the default set)."""
        p = finsler.default_pairs(self.metric) if pairs is None else check_pairs(
            self.metric, pairs)
        paths = self.generate(p[:, 0], p[:, 1], depth)
        return evaluate_paths(self.metric, paths, self.eps if eps is None else eps)


class ToyTrainer(RunLoop):
    """One iteration: a batch of pairs, ``directions`` antithetic random perturbations of
    the weights scored by the batch's mean path length, one step down the estimated
    gradient (random search: values of C only, model-free)."""

    config_class = ToyConfig
    label = "toy"
    free_on_resume = ("minutes", "device", "eval_pairs", "timesteps")

    def setup(self) -> None:
        # self.metric, self.device, self.validation_pairs, torch threads: the loop's
        with self.seeded():  # the initial weights from cfg.seed
            self.net = offset_net(self.metric.dim, self.cfg.hidden)
        self.rng, _ = self.generators()
        self.train_length = float("nan")

    def mean_length(self, theta: torch.Tensor, ends: torch.Tensor) -> float:
        """Mean length (sum of C) of the batch's paths with weights ``theta``."""
        vector_to_parameters(theta, self.net.parameters())
        with torch.no_grad():
            paths = toy_paths(self.net, self.metric, ends[:, 0], ends[:, 1],
                              self.cfg.max_depth)
            costs = self.metric.path_costs(paths)  # (batch, 2**D) evaluations of C
        self.timesteps += costs.numel()  # every evaluation counts
        self.timesteps_paper += costs.numel()
        return float(costs.sum(-1).mean())

    def iterate(self) -> None:
        cfg, dim = self.cfg, self.metric.dim
        ends = self.metric.domain.sample(2 * cfg.batch, self.rng).reshape(cfg.batch, 2, dim)
        ends = torch.as_tensor(ends, dtype=torch.float64)
        theta = parameters_to_vector(self.net.parameters()).detach()
        step, lengths = torch.zeros_like(theta), []
        for _ in range(cfg.directions):
            e = torch.as_tensor(self.rng.standard_normal(theta.numel()))
            plus = self.mean_length(theta + cfg.sigma * e, ends)
            minus = self.mean_length(theta - cfg.sigma * e, ends)
            step += (plus - minus) / (plus + minus) / (cfg.sigma * cfg.directions) * e
            lengths += [plus, minus]
        vector_to_parameters(theta - cfg.lr * step, self.net.parameters())
        self.train_length = float(np.mean(lengths))
        self.iteration += 1

    def evaluation(self) -> tuple[dict[str, Any], dict[str, Any]]:
        ev = ToyPolicy(self.net, self.cfg).evaluate(self.validation_pairs)
        return ({**eval_columns(ev), "train_length": round(self.train_length, 10)},
                best_record(ev, timesteps=self.timesteps))

    def state_dict(self) -> dict[str, Any]:  # all a resume needs
        return {"net": self.net.state_dict(), "rng": self.rng.bit_generator.state,
                "counters": {"train_length": self.train_length}}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.net.load_state_dict(state["net"])
        self.rng.bit_generator.state = state["rng"]
        self.train_length = float(state["counters"]["train_length"])

    def policy_state(self) -> dict[str, Any]:  # what checkpoint_best.pt keeps
        return {"net": self.net.state_dict()}

    def run_document(self) -> dict[str, Any]:  # config.json's sections on the method
        return {"objective": "mean path length (sum of C) by random search",
                "model_free": True, "uses_derivative_of_C": []}


def load_toy_policy(run_dir: Any, checkpoint: str = "best", device: str = "cpu",
                    env: str | None = None,
                    metric_params: dict[str, Any] | None = None) -> ToyPolicy:
    """The policy of a toy run directory (``checkpoint``: ``best`` or ``latest``)."""
    path, cfg, ckpt, loaded = load_run(run_dir, checkpoint, ToyConfig, ("toy",), env,
                                       metric_params)
    net = offset_net(cfg.metric.dim, cfg.hidden)
    load_weights(net, ckpt.get("net"), path)
    return ToyPolicy(net, cfg, source=str(path), checkpoint=loaded)


register_method(Method(
    name="toy", summary="straight-line midpoint plus a learned offset (an example)",
    config_class=ToyConfig, trainer=ToyTrainer, load_policy=load_toy_policy,
    default_config=ToyConfig))  # ToyConfig(env, **fields)
