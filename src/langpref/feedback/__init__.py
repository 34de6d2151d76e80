"""Kinds of feedback (paper Sec. 5.1: language and comparisons), their synthetic humans, and the world they answer in.

    from langpref.feedback import perfect_latent_space, sample_weights, LanguageHuman, LanguageQuery
    space = perfect_latent_space(dataset)                       # or build_latent_space(model, dataset)
    w = sample_weights(len(space.feature_names), seed=0)        # uniform on the unit sphere
    human = LanguageHuman(w, space.theta, space.table("test"), space.split("test"), space.feature_names, seed=0)
    human.answer(LanguageQuery(shown=5))                        # LanguageAnswer(text="Move faster.", ...)

Each kind is one module with one `FeedbackKind` (`kind.py`), registered by name: `get_kind("comparison")`; an
installed package adds one through the entry-point group `langpref.feedback`.
"""

from langpref.feedback.bradley_terry import PairBatch
from langpref.feedback.comparison import ComparisonAnswer, ComparisonHuman, ComparisonQuery
from langpref.feedback.humans import HumanConfig, normalised_reward, sample_weights, softmax, true_reward
from langpref.feedback.kind import (
    KINDS,
    FeedbackKind,
    StudyPage,
    get_kind,
    kind_names,
    kind_of,
    random_query,
    register_kind,
)
from langpref.feedback.language import LanguageAnswer, LanguageHuman, LanguageQuery
from langpref.feedback.space import (
    FeatureScale,
    LatentSpace,
    PhraseTable,
    build_latent_space,
    load_space,
    open_space,
    perfect_encoder,
    perfect_latent_space,
    phrase_table,
    toy_latent_space,
)

__all__ = [
    "KINDS",
    "ComparisonAnswer",
    "ComparisonHuman",
    "ComparisonQuery",
    "FeatureScale",
    "FeedbackKind",
    "HumanConfig",
    "LanguageAnswer",
    "LanguageHuman",
    "LanguageQuery",
    "LatentSpace",
    "PairBatch",
    "PhraseTable",
    "StudyPage",
    "build_latent_space",
    "get_kind",
    "kind_names",
    "kind_of",
    "load_space",
    "normalised_reward",
    "open_space",
    "perfect_encoder",
    "perfect_latent_space",
    "phrase_table",
    "random_query",
    "register_kind",
    "sample_weights",
    "softmax",
    "toy_latent_space",
    "true_reward",
]
