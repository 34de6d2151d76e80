"""Synthetic humans and the feedback they give (paper Sec. 5.1), and the world they give it in.

    from langpref.feedback import perfect_latent_space, sample_weights, LanguageHuman, LanguageQuery
    space = perfect_latent_space(dataset)                       # or build_latent_space(model, dataset)
    w = sample_weights(len(space.feature_names), seed=0)        # uniform on the unit sphere
    human = LanguageHuman(w, space.theta, space.table("test"), space.split("test"), space.feature_names, seed=0)
    human.answer(LanguageQuery(shown=5))                        # LanguageAnswer(text="Move faster.", ...)
"""

from langpref.feedback.humans import (
    ComparisonHuman,
    HumanConfig,
    LanguageHuman,
    normalised_reward,
    sample_weights,
    softmax,
    true_reward,
)
from langpref.feedback.space import (
    FeatureScale,
    LatentSpace,
    PhraseTable,
    build_latent_space,
    load_space,
    perfect_encoder,
    perfect_latent_space,
    phrase_table,
    toy_latent_space,
)
from langpref.feedback.types import Answer, ComparisonAnswer, ComparisonQuery, LanguageAnswer, LanguageQuery

__all__ = [
    "Answer",
    "ComparisonAnswer",
    "ComparisonHuman",
    "ComparisonQuery",
    "FeatureScale",
    "HumanConfig",
    "LanguageAnswer",
    "LanguageHuman",
    "LanguageQuery",
    "LatentSpace",
    "PhraseTable",
    "build_latent_space",
    "load_space",
    "normalised_reward",
    "perfect_encoder",
    "perfect_latent_space",
    "phrase_table",
    "sample_weights",
    "softmax",
    "toy_latent_space",
    "true_reward",
]
