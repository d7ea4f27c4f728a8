"""The paper's sequential baseline "Seq" (section 5.2, appendix B.2): goal-conditioned PPO.

`learn.seq.env`: the gymnasium environment of eqs. (57) and (14) (`GeodesicEnv`, and
`GeodesicVecEnv` stepping many copies at once); `learn.seq.config`: `SeqConfig`, the
paper's PPO settings; `learn.seq.policy`: deterministic rollouts, their evaluation and the
loaded policy; `learn.seq.trainer`: the stable-baselines3 trainer on the shared run loop
and the method's registration. Importing this package imports stable-baselines3.
"""

from learn.seq.config import SEGMENT_RTOL, SeqConfig, default_seq_config
from learn.seq.env import TIME_LIMITS, ZERO_ACTION_REWARD, GeodesicEnv, GeodesicVecEnv
from learn.seq.policy import SeqEvalResult, SeqPolicy, evaluate_seq, load_seq_policy, rollout
from learn.seq.trainer import WALL_COLUMNS, SeqTrainer, train_seq

__all__ = [
    "SEGMENT_RTOL",
    "TIME_LIMITS",
    "WALL_COLUMNS",
    "ZERO_ACTION_REWARD",
    "GeodesicEnv",
    "GeodesicVecEnv",
    "SeqConfig",
    "SeqEvalResult",
    "SeqPolicy",
    "SeqTrainer",
    "default_seq_config",
    "evaluate_seq",
    "load_seq_policy",
    "rollout",
    "train_seq",
]
