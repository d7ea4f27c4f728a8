"""learn: the midpoint-tree actor-critic of the paper (Algorithm 1) and its variants.

Train any method's config with `train_run` (a `TrainConfig` for the midpoint
learner: `default_config` gives the documented per-environment defaults; every
method's config extends [`RunConfig`][learn.RunConfig]); load a trained or shipped policy with
`load_policy` and generate paths with ``policy.generate(starts, goals)``, or with
the policy-guided route search ``policy.search(starts, goals)`` (`learn.midpoint.search`).
The paper's baselines sit beside the midpoint learner (`learn.seq.trainer` with its
gymnasium environment in `learn.seq.env`, `learn.pg.trainer`). Every method is a plug-in on
one run loop ([`learn.loop.RunLoop`][learn.loop.RunLoop]) registered in `learn.registry`, which the
CLI, sweeps and [`load_policy`][learn.load_policy] read; `learn.runs` trains and loads any method
and names the paper's variants, and `learn.midpoint.losses` holds the actor losses and extra
terms of the midpoint learner. A loaded policy of any method is a [`PathPolicy`][learn.PathPolicy]
(`MidpointPolicy` if it predicts midpoints); `learn.examples.toy_method` is a
whole method in one file, to copy.
"""

from finsler.status import RunAction, RunStatus, RunStop
from learn.base import TrainResult
from learn.evaluation import EvalResult, evaluate_paths
from learn.loop import RunLoop, resolve_device, shipped_policies
from learn.midpoint.config import (
    METHODS,
    TrainConfig,
    beyond_paper,
    default_config,
    package_versions,
    paper_config,
)
from learn.midpoint.networks import Actor, Critic
from learn.midpoint.policy import (
    Policy,
    critic_level_errors,
    evaluate_policy,
    export_policy,
    load_critic,
    load_midpoint_policy,
)
from learn.midpoint.search import SearchResult, SearchSpec, equalize_paths, search_paths
from learn.midpoint.trainer import Trainer, read_run_config, train
from learn.registry import (
    Method,
    MidpointPolicy,
    PathPolicy,
    Variant,
    get_method,
    list_methods,
    register_method,
)
from learn.run_config import RunConfig
from learn.runs import (
    VARIANTS,
    load_any_policy,
    load_policy,
    make_config,
    run_one,
    train_run,
)
from learn.storage import CorruptFileError
from learn.tree import build_tree, level_pairs, mc_targets, td_lambda_targets

__all__ = [
    "METHODS",
    "VARIANTS",
    "Actor",
    "CorruptFileError",
    "Critic",
    "EvalResult",
    "Method",
    "MidpointPolicy",
    "PathPolicy",
    "Policy",
    "RunAction",
    "RunConfig",
    "RunLoop",
    "RunStatus",
    "RunStop",
    "SearchResult",
    "SearchSpec",
    "TrainConfig",
    "TrainResult",
    "Trainer",
    "Variant",
    "beyond_paper",
    "build_tree",
    "critic_level_errors",
    "default_config",
    "equalize_paths",
    "evaluate_paths",
    "evaluate_policy",
    "export_policy",
    "get_method",
    "level_pairs",
    "list_methods",
    "load_any_policy",
    "load_critic",
    "load_midpoint_policy",
    "load_policy",
    "make_config",
    "mc_targets",
    "package_versions",
    "paper_config",
    "read_run_config",
    "register_method",
    "resolve_device",
    "run_one",
    "search_paths",
    "shipped_policies",
    "td_lambda_targets",
    "train",
    "train_run",
]
