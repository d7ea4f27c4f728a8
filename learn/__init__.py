"""learn: the midpoint-tree actor-critic of the paper (Algorithm 1), its variants and baselines.

Train any method's config with `train_run` (a `TrainConfig` for the midpoint learner:
`default_config` gives the documented per-environment defaults; every method's config
extends [`RunConfig`][learn.RunConfig]); load a trained or shipped policy with `load_policy`
and generate paths with ``policy.generate(starts, goals)``, or with the policy-guided route
search ``policy.search(starts, goals)``.

The package is a shared core with one folder per learning method:

* the core: `learn.run_config` (`RunConfig`, the fields every run has), `learn.loop`
  (the one run loop, [`RunLoop`][learn.RunLoop], and the loading of a run's checkpoint),
  `learn.registry` (the learning methods by name), `learn.runs` (train, load and track any
  method's runs by name or variant), `learn.sweep` (many runs on a pool or Ray),
  `learn.storage` (the run directory's files), `learn.evaluation` (the section 5.1
  evaluation of any method's paths), `learn.tree` (midpoint trees and their targets),
  `learn.base` (the loaded policy's base, the end of a run) and `learn.mlp`;
* `learn.midpoint`: the midpoint learner (config, networks, losses, route search, policy,
  trainer);
* `learn.seq`, `learn.pg`: the paper's baselines (goal-conditioned PPO with its gymnasium
  environment; per-depth policy gradient);
* `learn.examples.toy_method`: a whole method in one file, to copy.

A method never imports another method's folder: what two of them share is in the core.
A loaded policy of any method is a [`PathPolicy`][learn.PathPolicy] (`MidpointPolicy` if it
predicts midpoints).
"""

from finsler.status import RunAction, RunStatus, RunStop
from learn.base import TrainingInterrupted, TrainResult
from learn.evaluation import EvalResult, evaluate_paths
from learn.loop import RunLoop, resolve_device, shipped_policies
from learn.midpoint.config import (
    METHODS,
    TrainConfig,
    beyond_paper,
    default_config,
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
    import_method_modules,
    list_methods,
    register_method,
)
from learn.run_config import RunConfig, package_versions
from learn.runs import (
    VARIANTS,
    load_any_policy,
    load_policy,
    load_run_config,
    make_config,
    run_one,
    run_status,
    train_run,
    warm_start_paths,
)
from learn.storage import CorruptFileError
from learn.sweep import SWEEP_FILE, SweepPlan, SweepResult, plan_sweep, run_sweep
from learn.tree import build_tree, level_pairs, mc_targets, td_lambda_targets

__all__ = [
    "METHODS",
    "SWEEP_FILE",
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
    "SweepPlan",
    "SweepResult",
    "TrainConfig",
    "TrainResult",
    "Trainer",
    "TrainingInterrupted",
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
    "import_method_modules",
    "level_pairs",
    "list_methods",
    "load_any_policy",
    "load_critic",
    "load_midpoint_policy",
    "load_policy",
    "load_run_config",
    "make_config",
    "mc_targets",
    "package_versions",
    "paper_config",
    "plan_sweep",
    "read_run_config",
    "register_method",
    "resolve_device",
    "run_one",
    "run_status",
    "run_sweep",
    "search_paths",
    "shipped_policies",
    "td_lambda_targets",
    "train",
    "train_run",
    "warm_start_paths",
]
