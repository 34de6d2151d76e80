"""Reward learning from feedback: the learners, the loop that asks a (synthetic) person, active query selection, and
the saved reward other tools train on.

    learner.py       the paper's learner (Eq. 5-9, Eq. 11): r_xi fit to weighted Bradley-Terry pairs (`--learner paper`)
    answer_model.py  the trajectory-conditional answer-model learner: a particle belief over the reward
                     (`--learner answer-model`)
    loop.py          `langpref learn-reward`: Q queries per run, metrics after each, humans x seeds
    metrics.py       cross-entropy and the best trajectory's true reward (Sec. 5.1); Kendall's tau, EPIC distance and
                     value-order correlation, the metrics reward models are compared by elsewhere
    selection.py     active queries (`--query-selection`), scored on a posterior (`posterior.py`), in batches
                     (`batch.py`), over both kinds per modelled second (`mixed.py`, `cost.py`)
    api.py           the saved reward as a stable API: `load(PATH).compute_reward(observations, actions)`
    steps.py         the trajectory encoder per step, in numpy (what a saved reward and value-order read)
    saved.py         saving the learned reward (`--save-reward`) and a Gymnasium wrapper that trains on it
"""

from langpref.reward.api import Reward, load
from langpref.reward.curves import Curves, summarise_curves
from langpref.reward.learner import (
    DEFAULT_WEIGHT_DECAY,
    LOSSES,
    MODELS,
    NEGATIVES,
    LinearReward,
    MlpReward,
    RewardConfig,
    RewardLearner,
    RewardModel,
)
from langpref.reward.loop import LearnRewardConfig, feedback_choices, human_weights, learn_reward, run_reward_learning
from langpref.reward.metrics import cross_entropy, epic_distance, kendall_tau, reward_of_best, value_order_correlation

__all__ = [
    "DEFAULT_WEIGHT_DECAY",
    "LOSSES",
    "MODELS",
    "NEGATIVES",
    "Curves",
    "LearnRewardConfig",
    "LinearReward",
    "MlpReward",
    "RewardConfig",
    "RewardLearner",
    "Reward",
    "RewardModel",
    "cross_entropy",
    "epic_distance",
    "feedback_choices",
    "human_weights",
    "kendall_tau",
    "learn_reward",
    "load",
    "reward_of_best",
    "run_reward_learning",
    "summarise_curves",
    "value_order_correlation",
]
