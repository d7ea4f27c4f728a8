"""The PG baseline's config: `PGConfig` (appendix B.3's settings and the options that
reproduce the authors' code), `default_pg_config`, and the per-depth schedule of cycles
(`cycle_depth`, `schedule_total`)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from finsler.errors import InputError
from learn.run_config import (
    RunConfig,
    check_choice,
    check_hidden,
    ensure_registered,
    training_settings,
)

__all__ = ["SURROGATES", "PGConfig", "cycle_depth", "default_pg_config", "schedule_total"]

_OBJECTIVES = ("halves-squared", "sum")
SURROGATES = ("ppo", "sgt-pg-code")
_ACTIVATIONS = ("tanh", "relu")


@dataclass
class PGConfig(RunConfig):
    """Every setting of one PG training run (saved as ``config.json``): the run fields of
    `learn.run_config.RunConfig` (``timesteps``: the budget of evaluations of C,
    all-inclusive, here equal to the paper's count; None = the schedule's total,
    `schedule_total`, the paper's total for the environment; ``depth``: the number
    of policies D_max; ``eval_every``: cycles between evaluations, and every level's last
    cycle is evaluated too), then PG's own."""

    config_methods: ClassVar[tuple[str, ...]] = ("pg",)
    run_defaults: ClassVar[Mapping[str, Any]] = {"timesteps": None}

    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of every policy (paper: 64, 64)."""
    activation: str = "tanh"
    """``tanh`` (paper) or ``relu``."""
    normalize_inputs: bool = False
    """Beyond the paper: scale (s, g) to [-1, 1] by the domain's bounds before the MLP."""
    base_std: float = 0.05
    """Base standard deviation: std_i = Softplus(sigma_i) + (base_std + Softplus(c_i)) |s - g|."""
    init_c: float = 0.0
    """Initial value of the learnable c_i of the standard deviation."""
    lr: float = 5e-3
    """Adam learning rate (paper: 5e-3)."""
    pairs_per_cycle: int = 30
    """Start-goal pairs sampled per cycle (paper: 30)."""
    samples_per_pair: int = 10
    """Midpoints sampled from pi_D per pair (paper: 10); at least 2 (the baseline is their
    mean)."""
    clip: float = 0.2
    """PPO clipping parameter (paper: 0.2)."""
    entropy_coef: float = 1.0
    """Entropy coefficient (paper: 1)."""
    epochs: int = 1
    """Full-batch gradient steps per cycle (paper: 1)."""
    cycles_first: int | None = None
    """Cycles of pi_1; None = 1000 (Panda: 1077)."""
    cycles_other: int | None = None
    """Cycles of each pi_D, D >= 2; None = 538 (Panda: 1077). pi_Dmax keeps training if the
    budget is larger than the schedule."""
    objective: str = "halves-squared"
    """``halves-squared``: c_tau of eq. (15); ``sum``: the path length (the labels of the
    authors' SGT-PG code and of the original SGT-PG)."""
    surrogate: str = "ppo"
    """``ppo``: max(r A, clip(r, 1-clip, 1+clip) A); ``sgt-pg-code``: max(r A, (1+clip) A),
    what the authors' code computes."""
    init_from_lower: bool = True
    """Start pi_D from pi_{D-1}'s weights (the authors' code: init_from_lower_level)."""
    restore_level_best: bool = True
    """When pi_D's level ends, reset pi_D to its best state of the level on the validation
    set at depth D (success, then lower mean max segment cost), as the authors' code restores
    its best model at the end of each level."""
    swap_augment: bool = False
    """Also train on every pair reversed (g, s) with the same midpoint and advantage (the
    authors' code does; questionable for non-reversible metrics)."""
    def complete(self) -> None:
        """The schedule's defaults for the environment, and its total as the budget."""
        first, other = training_settings(self.env).pg_cycles
        if self.cycles_first is None:
            self.cycles_first = first
        if self.cycles_other is None:
            self.cycles_other = other
        if self.timesteps is None:
            self.timesteps = schedule_total(self)

    def validate(self) -> None:
        """Raise `InputError` naming the first impossible field of PG's own (the run
        fields are [`RunConfig`][learn.RunConfig]'s to check)."""
        check_choice("activation", self.activation, _ACTIVATIONS)
        check_choice("objective", self.objective, _OBJECTIVES)
        check_choice("surrogate", self.surrogate, SURROGATES)
        for name in ("pairs_per_cycle", "epochs", "cycles_first", "cycles_other"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        if self.samples_per_pair < 2:
            raise InputError("samples_per_pair must be at least 2 (the baseline is the mean "
                             f"of the pair's samples), got {self.samples_per_pair!r}")
        check_hidden(self.hidden)
        _real("lr", self.lr, 0.0, 1.0)
        _real("clip", self.clip, 0.0, 1.0)
        _real("base_std", self.base_std, 0.0, math.inf)
        if not (0.0 <= self.entropy_coef < math.inf):
            raise InputError(f"entropy_coef must be finite and >= 0, got {self.entropy_coef!r}")
        if not math.isfinite(self.init_c):
            raise InputError(f"init_c must be finite, got {self.init_c!r}")

    # ------------------------------------------------------------------------------------
    @property
    def model_free(self) -> bool:
        """Always True: PG uses values of C only."""
        return True

    def cycle_evaluations(self, depth: int) -> int:
        """Evaluations of C in one cycle at ``depth``: pairs * samples * 2**depth."""
        return self.pairs_per_cycle * self.samples_per_pair * 2**depth


def _real(name: str, value: float, lo: float, hi: float) -> None:
    """``lo < value < hi`` (open interval; hi may be inf)."""
    if not (lo < value < hi):
        raise InputError(f"{name} must be in ({lo:g}, {hi:g}), got {value!r}")


def default_pg_config(env: str, **overrides: Any) -> PGConfig:
    """The paper's PG settings (appendix B.3) for ``env``; ``overrides`` replace fields."""
    ensure_registered(env, overrides.get("metric_class"))
    return PGConfig(env=env, **overrides)


def cycle_depth(cfg: PGConfig, cycle: int) -> int:
    """Depth D of the policy trained in the ``cycle``-th cycle (0-based): 1 for the first
    ``cycles_first`` cycles, then ``cycles_other`` cycles per depth, Dmax for ever after."""
    assert cfg.cycles_first is not None and cfg.cycles_other is not None
    if cycle < cfg.cycles_first:
        return 1
    return min(2 + (cycle - cfg.cycles_first) // cfg.cycles_other, cfg.max_depth)


def schedule_total(cfg: PGConfig) -> int:
    """Evaluations of C of the whole schedule (the paper's total, appendix B.3):
    ``P * K * (2 * cycles_first + sum_{D=2..Dmax} 2**D * cycles_other)``."""
    first, other = training_settings(cfg.env).pg_cycles
    cf = cfg.cycles_first if cfg.cycles_first is not None else first
    co = cfg.cycles_other if cfg.cycles_other is not None else other
    per = cfg.pairs_per_cycle * cfg.samples_per_pair
    return per * (2 * cf + sum(2**d * co for d in range(2, cfg.max_depth + 1)))


