"""The Seq baseline's config: `SeqConfig` (the paper's PPO settings of appendix B.2 and
the environment's), `default_seq_config`, and what ``config.json`` says about a run."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import finsler
from finsler.errors import InputError
from learn.run_config import (
    RunConfig,
    check_hidden,
    ensure_registered,
    package_versions,
    training_settings,
)
from learn.seq.env import TIME_LIMITS

__all__ = ["SEGMENT_RTOL", "SeqConfig", "default_seq_config", "run_document"]

#: Relative tolerance on the segment test ``C(p_i, p_i+1) <= eps`` of Seq's paths: every
#: step of eq. (57) has ``C = eps`` exactly in exact arithmetic, ``eps * (1 +- 1e-16)`` in
#: float64 (see `evaluate_seq`).
SEGMENT_RTOL = 1e-9


#: 16 batched copies of the environment: about 4x the steps per second of SB3's single
#: environment with the paper's settings on 2 cores, and 32 are no faster (PPO's minibatch
#: updates then dominate). The rollout per update stays SB3's 2048 steps (16 x 128).
_DEFAULT_N_ENVS = 16
_PAPER_ROLLOUT = 2048


@dataclass
class SeqConfig(RunConfig):
    """Every setting of one Seq run (saved as ``config.json``): the run fields of
    `learn.run_config.RunConfig` (``seed`` also seeds SB3's global generators and
    the environments, copy ``i`` with ``seed + i``; ``timesteps``: the budget of
    ALL-INCLUSIVE evaluations of F or C made by the environments, 3 per step and 2 per
    reset candidate; paper: 2e7 (Matsumoto, Panda), 8e7 (car-like) env steps; ``device``
    is SB3's networks', the environments run on numpy; ``depth``: episodes last at most
    ``2**depth`` steps, paper n = 2**D_max; ``eps``: the step cost of eq. (57) and the
    success threshold; ``eval_every``: all-inclusive timesteps between evaluations,
    checked after every rollout), then Seq's own. PPO settings not listed are
    stable-baselines3's defaults (normalised advantages, orthogonal initialisation, log-std
    initialised at 0, no target KL, no value clipping)."""

    config_methods: ClassVar[tuple[str, ...]] = ("seq",)
    run_defaults: ClassVar[Mapping[str, Any]] = {"eval_every": 200_000}

    reject_solved: bool = True
    """Redraw start/goal pairs already within eps (the authors' code does)."""
    lr: float = 3e-3
    """Adam learning rate (paper: 3e-3, searched over 3e-2, 3e-3, 3e-4)."""
    batch_size: int = 128
    """PPO minibatch size (paper: 128, searched over 64, 128, 256)."""
    gamma: float = 1.0
    """Discount factor (paper: 1)."""
    n_envs: int = _DEFAULT_N_ENVS
    """Environment copies stepped together (paper: SB3's single environment)."""
    n_steps: int = _PAPER_ROLLOUT // _DEFAULT_N_ENVS
    """Steps per copy per rollout; ``n_envs * n_steps`` = 2048, SB3's default rollout."""
    n_epochs: int = 10
    """PPO epochs per rollout (SB3 default)."""
    time_limit: str = "truncate"
    """What the step limit ``n`` is to PPO: ``truncate`` (gymnasium's ``truncated``: SB3
    bootstraps the last step with the critic's value) or ``terminate`` (the episode ends as
    if absorbed, no bootstrap: the authors' gym-0.21 code)."""
    gae_lambda: float = 0.95
    """GAE lambda (SB3 default)."""
    clip_range: float = 0.2
    """PPO clip range (SB3 default)."""
    ent_coef: float = 0.0
    """Entropy coefficient (SB3 default)."""
    vf_coef: float = 0.5
    """Value-loss coefficient (SB3 default)."""
    max_grad_norm: float = 0.5
    """Gradient clipping (SB3 default)."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layers of the actor and of the critic (paper: 64, 64)."""
    activation: str = "tanh"
    """``tanh`` (paper, SB3's default) or ``relu``."""
    def validate(self) -> None:
        """Raise `finsler.InputError` naming the first impossible field of Seq's
        own (the run fields are [`RunConfig`][learn.RunConfig]'s to check)."""
        for name in ("batch_size", "n_envs", "n_steps", "n_epochs"):
            v = getattr(self, name)
            if v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        if not (0 < self.lr < 1):
            raise InputError(f"lr must be in (0, 1), got {self.lr!r}")
        if self.time_limit not in TIME_LIMITS:
            raise InputError(f"time_limit must be one of {', '.join(TIME_LIMITS)}, got "
                             f"{self.time_limit!r}")
        if not (0 < self.gamma <= 1):
            raise InputError(f"gamma must be in (0, 1], got {self.gamma!r}")
        if not (0 <= self.gae_lambda <= 1):
            raise InputError(f"gae_lambda must be in [0, 1], got {self.gae_lambda!r}")
        if not (0 < self.clip_range < math.inf):
            raise InputError(f"clip_range must be positive and finite, got {self.clip_range!r}")
        for name in ("ent_coef", "vf_coef"):
            v = getattr(self, name)
            if not (0 <= v < math.inf):
                raise InputError(f"{name} must be finite and >= 0, got {v!r}")
        if not (0 < self.max_grad_norm < math.inf):
            raise InputError(f"max_grad_norm must be positive and finite, got "
                             f"{self.max_grad_norm!r}")
        check_hidden(self.hidden)
        if self.activation not in ("tanh", "relu"):
            raise InputError(f"activation must be one of tanh, relu; got {self.activation!r}")
        if self.n_envs * self.n_steps < 2:
            raise InputError("n_envs * n_steps must be at least 2 (PPO normalises advantages)")
        if self.batch_size > self.n_envs * self.n_steps:
            raise InputError(f"batch_size ({self.batch_size}) must not exceed the rollout "
                             f"n_envs * n_steps ({self.n_envs * self.n_steps})")

    @property
    def model_free(self) -> bool:
        """Seq uses values of F and C only (rewards, steps, termination)."""
        return True


def default_seq_config(env: str, **overrides: Any) -> SeqConfig:
    """The paper's Seq settings for ``env`` (appendix B.2; budget 2e7, car-like 8e7) with
    this toolkit's batched environments (``n_envs`` x ``n_steps`` = SB3's 2048-step
    rollout); ``overrides`` replace fields (unknown ones raise `InputError`)."""
    ensure_registered(env, overrides.get("metric_class"))
    # the paper's budget for the metric's task (Metric.training.paper_timesteps)
    settings: dict[str, Any] = {"env": env,
                                "timesteps": training_settings(env).paper_timesteps}
    if "n_envs" in overrides and "n_steps" not in overrides:
        n = overrides["n_envs"]
        if isinstance(n, int) and not isinstance(n, bool) and n >= 1:
            settings["n_steps"] = max(1, _PAPER_ROLLOUT // n)
    settings.update(overrides)
    names = {f.name for f in dataclasses.fields(SeqConfig)}
    unknown = sorted(set(settings) - names)
    if unknown:
        raise InputError(f"unknown config field(s): {', '.join(unknown)}")
    return SeqConfig(**settings)


def _paper_differences(cfg: SeqConfig) -> dict[str, dict[str, Any]]:
    paper = {"lr": 3e-3, "batch_size": 128, "gamma": 1.0, "n_envs": 1, "n_steps": 2048,
             "n_epochs": 10, "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.0,
             "vf_coef": 0.5, "max_grad_norm": 0.5, "hidden": [64, 64], "activation": "tanh"}
    d = cfg.to_dict()
    return {k: {"used": d[k], "paper": v} for k, v in paper.items() if d[k] != v}


def run_document(cfg: SeqConfig) -> dict[str, Any]:
    """``config.json``'s sections about Seq."""
    import gymnasium as gym
    import stable_baselines3 as sb3

    return {
        "model_free": True,
        "uses_derivative_of_C": [],
        "counts": "timesteps = every evaluation of F or C made by the environments during "
                  "training (3 per step with a non-zero action, 0 for a zero action, 2 per "
                  "start/goal candidate at a reset); timesteps_paper = environment steps "
                  "(the paper's count); timesteps_derivative = 0",
        "selection": f"checkpoint_best by success on finsler.validation_pairs (seed "
                     f"{finsler.VALIDATION_SEED}, {cfg.eval_pairs} pairs)",
        "success": "path p_0..p_j, g (at most 2**D segments) with every C <= eps * "
                   f"(1 + {SEGMENT_RTOL:g}); reached_rate = the paper's episode success "
                   "(C(p_j, g) < eps within 2**D steps)",
        "versions": {**package_versions(), "stable_baselines3": sb3.__version__,
                     "gymnasium": gym.__version__},
        "beyond_paper": _paper_differences(cfg),
    }


