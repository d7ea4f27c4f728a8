"""The midpoint-tree actor-critic of the paper (Algorithm 1) and its variants.

* `learn.midpoint.config`: `TrainConfig`, the per-environment defaults and the paper's
  settings;
* `learn.midpoint.networks`: the actor and critic networks;
* `learn.midpoint.losses`: the actor losses of eqs. (6), (17), (18) and the extra actor
  terms; `learn.midpoint.term`: the contract of such a term;
  `learn.midpoint.expert`: the expert-iteration term;
* `learn.midpoint.search`: the policy-guided route search;
* `learn.midpoint.policy`: the loaded policy, its loader, the critic, export;
* `learn.midpoint.trainer`: `Trainer` (Algorithm 1 on the shared run loop) and the
  method's registration (``midpoint``, ``inter``, ``two-to-one`` and their variants).

The public names are importable from `learn`.
"""

from learn.midpoint.config import METHODS, TrainConfig, beyond_paper, default_config, paper_config
from learn.midpoint.policy import Policy, load_critic, load_midpoint_policy
from learn.midpoint.search import SearchResult, SearchSpec, equalize_paths, search_paths
from learn.midpoint.trainer import Trainer, read_run_config, train

__all__ = [
    "METHODS",
    "Policy",
    "SearchResult",
    "SearchSpec",
    "TrainConfig",
    "Trainer",
    "beyond_paper",
    "default_config",
    "equalize_paths",
    "load_critic",
    "load_midpoint_policy",
    "paper_config",
    "read_run_config",
    "search_paths",
    "train",
]
