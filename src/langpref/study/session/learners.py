"""Study 2's reward learners (`StudyConfig.learner`) for live participants, and what the model reads in a sentence.

- `paper` (`langpref.reward.RewardLearner`): each answer becomes its kind's Bradley-Terry pairs (Eq. 5-9, Eq. 11),
  refit after every answer;
- `answer-model` (`langpref.reward.answer_model.AnswerModelLearner`): a particle belief over the reward, language read
  given the trajectory it was said about, comparisons in the same belief; `fit` after every answer, replayed ones
  included, so that a learner rebuilt from the database resamples when the running one did and equals it.

`Meanings` is the model's reading of a typed sentence over the 2F meanings (feature, direction) of the study's bank
split: P(meaning | text) (`langpref.reward.answer_model.AnswerReader`, the same reading the answer-model learner
uses), each meaning's words for the participant, and its mean psi. A participant who confirms a meaning
(`--confirm-margin`) teaches the learner that meaning: the answer-model learner observes it in place of its reading;
the paper's learner builds the answer's pairs with psi the bank's mean psi of that meaning. "None of these" is
stored and not learned from.

`learned_reward` is what the export holds of a learner: its latent weights xi (r = xi . phi, plus a constant), for
the answer-model learner also its weights v over the bank's feature axes, and its ranking of the study set.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from langpref.feedback.space import LatentSpace
from langpref.language.bank import DIRECTIONS
from langpref.reward.answer_model import AnswerReader
from langpref.reward.selection import feature_axes


class Meanings:
    """The 2F meanings of bank split `split` (meaning 2k + d: feature `features[k]`, d = 0 increase, 1 decrease), and
    the model's soft reading of a sentence over them (T_read fitted on the bank as the answer-model learner does)."""

    def __init__(self, space: LatentSpace, split: str):
        self.space = space
        self.features, _ = feature_axes(space, split)
        self.reader = AnswerReader(space, self.features, split, None)
        table = space.table(split)
        psi, words = [], []
        for f in self.features:
            for d in range(len(DIRECTIONS)):
                rows, other = table.rows(int(f), d), table.rows(int(f), 1 - d)
                mean = table.psi[rows].mean(axis=0) if len(rows) else -table.psi[other].mean(axis=0)
                psi.append(mean)
                words.append(_typical(table, rows, mean) if len(rows) else None)
        self.psi = np.stack(psi)
        self.words = words

    def __len__(self) -> int:
        return len(self.psi)

    @property
    def temperature(self) -> float:
        return self.reader.temperature

    def reading(self, psi: np.ndarray) -> np.ndarray:
        """P(meaning | sentence) (2F,) of the sentence embedded as `psi`."""
        return np.exp(self.reader.log_probabilities(np.asarray(psi, dtype=np.float64)))

    def feature(self, meaning: int) -> str:
        return self.space.feature_names[int(self.features[int(meaning) // 2])]

    def direction(self, meaning: int) -> str:
        return DIRECTIONS[int(meaning) % 2]

    def label(self, meaning: int) -> str:
        """The meaning in words for a participant: its most typical bank phrasing, then (feature, direction), e.g.
        "move faster (speed, increase)"."""
        feature, direction = self.feature(meaning), self.direction(meaning)
        words = self.words[int(meaning)] or f"{direction} {feature.replace('_', ' ')}"
        return f"{words} ({feature}, {direction})"

    def group(self, meaning: int) -> int:
        """The meaning as a phrase table's group (2 * dataset feature index + direction)."""
        return 2 * int(self.features[int(meaning) // 2]) + int(meaning) % 2

    @staticmethod
    def margin(reading: np.ndarray) -> float:
        """P of the top reading minus P of the second."""
        top = np.sort(np.asarray(reading))[::-1]
        return float(top[0] - (top[1] if len(top) > 1 else 0.0))

    @staticmethod
    def top(reading: np.ndarray, n: int) -> list[int]:
        """The `n` likeliest meanings, likeliest first (ties: the lower index)."""
        return [int(m) for m in np.argsort(-np.asarray(reading), kind="stable")[:n]]


INDIRECT = frozenset({"too", "not", "no", "never", "stop", "quit", "dont"})
"""Words of a phrasing that says its meaning indirectly (a complaint, a negation): not used to name a meaning."""


def _typical(table, rows: np.ndarray, mean: np.ndarray) -> str:
    """The meaning in a few words: its shortest plain phrasing among `rows` (two words or more, preferably no
    complaint or negation such as "too slow" or "don't stop", which read the other way round out of context; ties:
    the one nearest the meaning's mean psi), with a lower-case start and no final stop ("move faster")."""
    psi = table.psi[rows]
    cos = psi @ mean / np.maximum(np.linalg.norm(psi, axis=1) * max(float(np.linalg.norm(mean)), 1e-12), 1e-12)
    keys = []
    for r, c in zip(rows, cos):
        words = table.texts[int(r)].lower().replace("n't", " not").split()
        indirect = bool(set(words) & INDIRECT)
        keys.append((indirect, len(words) < 2, len(table.texts[int(r)]), -float(c), int(r)))
    text = table.texts[min(keys)[-1]].strip().rstrip(".!")
    return text[:1].lower() + text[1:] if text[1:2].islower() or len(text) < 2 else text


def learned_reward(learner: Any, space: LatentSpace, study: np.ndarray, name: str) -> dict[str, Any]:
    """What the export holds of a learner (module docstring): `latent_weights` xi (D,), `feature_weights` {feature:
    v_f} (answer-model) or None, and `ranking`, the study set's dataset indices by learned reward, best first."""
    from langpref.reward.learners import learner_type_of

    reward = np.asarray(learner.predict(space.phi[study]), dtype=np.float64)
    ranking = [int(i) for i in study[np.argsort(-reward, kind="stable")]]
    learner_type = learner_type_of(learner)
    kind, params, _ = learner_type.saved(learner)
    xi = params["xi"] if kind == "linear" else []  # a reward that is not linear in phi has no latent weights
    v = None if learner_type.feature_weights is None else learner_type.feature_weights(learner, space)
    return {"learner": name, "latent_weights": [float(x) for x in xi], "feature_weights": v, "ranking": ranking}
