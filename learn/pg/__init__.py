"""The paper's policy-gradient baseline "PG" (section 5.2, eqs. (15)-(16), appendix B.3).

`learn.pg.trainer`: per-depth policies (`DepthPolicy`), the clipped policy-gradient loss,
the trainer on the shared run loop, the loaded policy, and the method's registration.
"""

from learn.pg.trainer import (
    DepthPolicy,
    PGConfig,
    PGPolicy,
    PGTrainer,
    c_tau,
    cycle_depth,
    default_pg_config,
    gaussian_entropy,
    gaussian_log_prob,
    generate_pg_paths,
    load_pg_policy,
    pair_baseline,
    pg_loss,
    sample_training_paths,
    schedule_total,
    train_pg,
)

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
