"""The paper's policy-gradient baseline "PG" (section 5.2, eqs. (15)-(16), appendix B.3).

`learn.pg.config`: `PGConfig` and the per-depth schedule; `learn.pg.policy`: the per-depth
policies (`DepthPolicy`), path completion and the loaded policy; `learn.pg.losses`: the
objective of eq. (15), the baseline of eq. (16) and the clipped surrogate;
`learn.pg.trainer`: the trainer on the shared run loop and the method's registration.
"""

from learn.pg.config import PGConfig, cycle_depth, default_pg_config, schedule_total
from learn.pg.losses import c_tau, gaussian_entropy, gaussian_log_prob, pair_baseline, pg_loss
from learn.pg.policy import (
    DepthPolicy,
    PGPolicy,
    generate_pg_paths,
    load_pg_policy,
    sample_training_paths,
)
from learn.pg.trainer import PGTrainer, train_pg

__all__ = [
    "DepthPolicy",
    "PGConfig",
    "PGPolicy",
    "PGTrainer",
    "c_tau",
    "cycle_depth",
    "default_pg_config",
    "gaussian_entropy",
    "gaussian_log_prob",
    "generate_pg_paths",
    "load_pg_policy",
    "pair_baseline",
    "pg_loss",
    "sample_training_paths",
    "schedule_total",
    "train_pg",
]
