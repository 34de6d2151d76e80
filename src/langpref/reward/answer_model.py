"""The answer-model learner (`--learner answer-model`): a belief over the reward that reads a sentence as evidence
about the reward *given the trajectory it was said about*, asks actively under that same model, and holds language
and comparisons in one posterior.

Why. Under the paper's learner (Eq. 5-9) with a linear r_xi, r(phi + psi_l) - r(phi) = xi . psi_l: phi of the shown
trajectory cancels out of every pair, so the learner learns only how often each meaning is named, and a strategy
that chooses what to show distorts those counts (docs/results.md, "Active queries on the default data").

The reward. Each feature f the bank has phrasings of gets an axis a_f in the latent space (from the mean psi of its
`decrease` phrasings to that of its `increase` ones, over the robot's own bank split; `feature_axes`). A trajectory's
reading along the axes, standardised over the query pool, is z_f(tau) = (a_f . phi(tau) - mu_f) / sd_f, and the
reward is r_v(tau) = v . z(tau), v in R^F. As a reward on phi it is linear, xi = sum_f (v_f / sd_f) a_f (plus a
constant), so it is saved and used like the paper's linear reward.

The likelihood of a language answer l about tau is normalised over the 2F meanings m = (feature, direction) the
person could have meant:

    P(l | v, tau) = sum_m P(m | l) P(m | v, tau)
    P(f | v, tau) = softmax over f and "no change" of ( v_f (z_f(tau*_v) - z_f(tau)) / T ; c ),   tau*_v = argmax r_v
    P(d | f, v)   = 1 - slip for the direction that raises r_v (sign of v_f), slip for the other
    P(m | v, tau) = (1 - lapse) P(f | v, tau) P(d | f, v) + lapse / (2F + 1)

and one more meaning, "that's good, no change" (a button in the study, never read from text), whose logit beside the
features' is a constant c (`no_change_logit`): likely only where every v_f (z_f(tau*_v) - z_f(tau)) is small, near
the belief's optimum, so hearing it says tau is nearly the best, and hearing a feature says it is not.

P(m | l) is the model's soft reading of the sentence: softmax over meanings of cos(psi_l, prototype_m) / T_read,
prototypes the mean psi of each meaning's phrasings in the robot's bank split, T_read fitted to the bank's own val
phrasings (their meanings are the bank's labels, never a synthetic human's; when the human speaks val phrasings, the
prototypes' split read leave-one-out instead, `AnswerReader`). P(f | v, tau) is the paper's Eq. 10
in the latent space: it depends on tau, so showing a trajectory that is already far along feature f makes "more f"
strong evidence and "more g" evidence that g matters more. `slip` and `lapse` make the model robust to people it does
not describe (a human who says the direction toward the best trajectory, or something vague).

A comparison's likelihood is Bradley-Terry on the same reward, sigmoid(beta (r_v(preferred) - r_v(rejected))).

The belief. Weighted particles v ~ N(0, prior_scale^2 I) (the scale is learned with the direction: a sharper person
is a larger v), reweighted by each answer's likelihood; when the effective sample size falls below half, they are
resampled and moved by a few Metropolis steps on the full posterior (resample-move), so the belief keeps contracting
as answers arrive. The learned reward is the posterior mean of v. Everything random draws from the learner's seed.

Active selection (`AnswerModelInfoGain`, `--query-selection infogain`) scores the mutual information between v and
the person's answer under this same model, from draws of the belief: for a language query, over the meaning the
model will read, through its confusion of meanings on the bank's held-out phrasings (a trajectory whose answer is
already certain, such as the belief's own optimum, scores 0 whatever was shown before; a meaning often misread is
worth less); for a comparison, over the binary choice; for `--feedback mixed`, both in nats per modelled second.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.space import ALL_SPLITS, LatentSpace, PhraseTable
from langpref.language.bank import DIRECTIONS
from langpref.reward.batch import Scored, join
from langpref.reward.readings import reading_of
from langpref.reward.selection import (
    Selector,
    binary_mutual_information,
    candidate_rows,
    feature_axes,
    mutual_information,
)

READING_TEMPERATURES = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)
"""The grid T_read is fitted on."""


@dataclass
class AnswerModelConfig:
    """The answer-model learner's knobs (`--learner answer-model`)."""

    particles: int = 2048
    """Particles of the belief over the reward weights v."""
    answer_temperature: float = 1.0
    """T of the answer model's softmax over features (Eq. 10's is 1)."""
    direction_slip: float = 0.1
    """Probability that the person names the direction of a feature that lowers the reward (or says the direction
    toward the best trajectory instead)."""
    lapse: float = 0.05
    """Probability that an answer says nothing about the reward (uniform over meanings: vague, misheard)."""
    reading_temperature: float | None = None
    """T_read of P(meaning | sentence) = softmax(cos(psi_l, prototype_m) / T_read); None: fitted on the bank's val
    phrasings, or on the prototypes' split left-one-out where the person speaks val or the bank has none
    (`AnswerReader`)."""
    comparison_rationality: float = 1.0
    """beta of a comparison's Bradley-Terry likelihood in the same belief."""
    no_change_logit: float = 0.0
    """c, the logit of "that's good, no change" beside the feature logits v_f (z_f(tau*) - z_f(tau)) / T: at the
    belief's optimum, where every feature logit is 0, it has 1 / (F + 1). 0 was chosen on val with other humans than
    the test runs' (`langpref experiment choose`, Meta-World and the drawer), against not modelling it (c = -30) and
    1, 2: the lowest or level cross-entropy for the paper's human and for one who says it (docs/results.md, "Val with
    other humans")."""
    prior_scale: float = 0.5
    """Standard deviation of the Gaussian prior on each reward weight. 0.5 was chosen on val with other humans than
    the test runs' (`langpref experiment choose`; Meta-World and the drawer, language and comparisons): the lowest
    mean CE in every row, where 1.0 made the learned reward overconfident (docs/results.md, "Val with other
    humans")."""
    move_steps: int = 4
    """Metropolis steps per particle after each resampling."""

    def validate(self) -> None:
        if self.particles < 16 or self.move_steps < 0:
            raise LangprefError("the answer-model learner needs particles >= 16 and move_steps >= 0")
        if not (0 <= self.direction_slip < 0.5 and 0 <= self.lapse < 1):
            raise LangprefError("direction_slip must be in [0, 0.5) and lapse in [0, 1)")
        if not (self.answer_temperature > 0 and self.prior_scale > 0 and self.comparison_rationality >= 0):
            raise LangprefError("answer_temperature and prior_scale must be > 0, comparison_rationality >= 0")
        if self.reading_temperature is not None and not self.reading_temperature > 0:
            raise LangprefError(f"reading_temperature must be > 0, got {self.reading_temperature}")


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), 1e-12)


def _log_softmax(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return x - np.logaddexp.reduce(x, axis=axis, keepdims=True)


class AnswerReader:
    """P(meaning | sentence): the model's soft reading of a sentence over the 2F meanings of the answer model
    (meaning 2k + d: feature `features[k]`, d = 0 increase), its prototypes the mean psi of each meaning's phrasings
    in the bank split `split`.

    How sentences are read (T_read and the confusion) is fitted on phrasings whose meaning the bank knows and that
    the person being read does not speak: the bank's val split; when the person speaks it (`spoken`: a synthetic
    human's `val` or `all`) or the bank has none, the prototypes' own split, each phrasing left out of its own
    meaning's prototype, so that no sentence is read against a prototype it helped make."""

    def __init__(
        self, space: LatentSpace, features: np.ndarray, split: str, temperature: float | None, spoken: str | None = None
    ):
        self.features = np.asarray(features)
        self.table = space.table(split)
        self.prototypes = _prototypes(self.table, self.features)
        cos, target = self.held_out(space, split, spoken)
        self.temperature = _best_temperature(cos, target) if temperature is None else float(temperature)
        self.confusion = _confusion(cos, target, len(self.prototypes))

    def log_probabilities(self, psi: np.ndarray) -> np.ndarray:
        """(..., 2F) log P(m | l) of embeddings psi (..., D)."""
        return _log_softmax((_unit(psi) @ self.prototypes.T) / self.temperature)

    def held_out(self, space: LatentSpace, split: str, spoken: str | None) -> tuple[np.ndarray, np.ndarray]:
        """(cos (n, 2F) of each fitting phrasing to every prototype, its meaning (n,)): the bank's val phrasings,
        or the prototypes' own split read leave-one-out (class docstring)."""
        try:
            table = space.table("val")
        except (KeyError, LangprefError):
            table = None
        own = table is None or spoken in ("val", ALL_SPLITS)
        table = self.table if own else table
        position = {int(f): k for k, f in enumerate(self.features)}
        alone = {f for f, n in zip(*np.unique(table.feature, return_counts=True)) if own and n < 2}
        rows = [i for i, f in enumerate(table.feature) if int(f) in position and f not in alone]
        target = np.array([2 * position[int(table.feature[i])] + int(table.direction[i]) for i in rows], np.int64)
        if not own:
            return _unit(table.psi[rows]) @ self.prototypes.T, target
        cos = np.stack([_unit(table.psi[i]) @ _prototypes(table, self.features, drop=i).T for i in rows])
        return cos.reshape(len(rows), len(self.prototypes)), target


def _prototypes(table: PhraseTable, features: np.ndarray, drop: int | None = None) -> np.ndarray:
    """(2F, D) the unit mean psi of each meaning's phrasings of `table` (row `drop` left out); a meaning without
    phrasings is the opposite of its feature's other direction."""
    keep = np.ones(len(table.feature), dtype=bool)
    if drop is not None:
        keep[drop] = False
    protos = []
    for f in features:
        inc, dec = (table.rows(int(f), d) for d in (0, 1))
        inc, dec = inc[keep[inc]], dec[keep[dec]]
        p_inc = _unit(table.psi[inc].mean(axis=0)) if len(inc) else None
        p_dec = _unit(table.psi[dec].mean(axis=0)) if len(dec) else None
        if p_inc is None and p_dec is None:
            raise LangprefError(f"feature {int(f)} has no phrasings to read answers against")
        protos += [p_inc if p_inc is not None else -p_dec, p_dec if p_dec is not None else -p_inc]
    return np.stack(protos)


def _confusion(cos: np.ndarray, target: np.ndarray, m: int) -> np.ndarray:
    """(2F + 1, 2F + 1) P(read as r | meant m): how often the held-out phrasings of each meaning are read (argmax)
    as each meaning, with one pseudo-count on the diagonal and a tenth on every cell; "no change" is never misread.
    Active selection scores the information in what is *read*, so a meaning often misread is worth less to ask
    about."""
    counts = np.eye(m) + 0.1
    if len(target):
        np.add.at(counts, (target, cos.argmax(axis=1)), 1.0)
    out = np.eye(m + 1)  # "no change" is a button: never misread, never read into
    out[:m, :m] = counts / counts.sum(axis=1, keepdims=True)
    return out


def _best_temperature(cos: np.ndarray, target: np.ndarray) -> float:
    """The T_read of `READING_TEMPERATURES` under which the held-out phrasings are likeliest as their own
    meanings."""
    if not len(target):
        return 0.1
    scores = [_log_softmax(cos / t)[np.arange(len(target)), target].mean() for t in READING_TEMPERATURES]
    return float(READING_TEMPERATURES[int(np.argmax(scores))])


CONFIRM_OPTIONS = 3
"""How many of the model's top readings a person confirming a sentence chooses among (or "none of these")."""


def confirm(learner: AnswerModelLearner, answer: Any, margin: float) -> tuple[bool, int | None]:
    """Ask when unsure: (asked, meaning). When the top two of the model's reading of `answer` are closer than
    `margin`, the person is shown the `CONFIRM_OPTIONS` top readings and clicks the one they meant (a synthetic human
    clicks the meaning it spoke, if shown), or "none of these" (meaning None: the answer is not learned from). When
    sure, (False, the top reading). "No change" was clicked, never read: (False, its meaning)."""
    if answer.no_change:
        return False, learner.no_change
    reading = learner.reading(answer.text)
    order = np.argsort(-reading)
    if reading[order[0]] - reading[order[1]] >= margin:
        return False, int(order[0])
    if answer.feature is None or answer.direction is None:
        raise LangprefError("a confirmation needs the person's meaning (a synthetic human's feature and direction)")
    meant = learner.meaning_index(learner.space.feature_names.index(answer.feature), DIRECTIONS.index(answer.direction))
    return True, meant if meant in order[:CONFIRM_OPTIONS] else None


class AnswerModelLearner:
    """The belief over v (module docstring): `observe` answers of either kind, `fit` folds them in, `predict` the
    posterior-mean reward of latent points phi, `draw` samples of the belief for active selection."""

    def __init__(
        self,
        space: LatentSpace,
        pool: Sequence[int],
        cfg: AnswerModelConfig | None = None,
        bank_split: str = "train",
        seed: int = 0,
        spoken: str | None = None,
    ):
        self.cfg = cfg or AnswerModelConfig()
        self.cfg.validate()
        self.space = space
        self.pool = np.asarray(pool, dtype=np.int64)
        self.features, axes = feature_axes(space, bank_split)
        proj = space.phi @ axes.T
        self.mu = proj[self.pool].mean(axis=0)
        self.sd = np.maximum(proj[self.pool].std(axis=0), 1e-9)
        self.axes = axes
        self.z = (proj - self.mu) / self.sd
        self.z_pool = self.z[self.pool]
        self.reader = AnswerReader(space, self.features, bank_split, self.cfg.reading_temperature, spoken)
        self.rng = np.random.default_rng(seed)
        self.v = self.cfg.prior_scale * self.rng.standard_normal((self.cfg.particles, len(self.features)))
        self.log_weights = np.zeros(self.cfg.particles)
        self.best = self._best(self.v)
        self.answers: list[tuple] = []
        self._pending: list[tuple] = []

    # ---- the answer model --------------------------------------------------------------------------------------

    @property
    def num_features(self) -> int:
        return len(self.features)

    @property
    def num_queries(self) -> int:
        return len(self.answers) + len(self._pending)

    def _best(self, v: np.ndarray) -> np.ndarray:
        """(n,) position in the pool of tau*_v for each row of v."""
        return np.argmax(v @ self.z_pool.T, axis=1)

    @property
    def no_change(self) -> int:
        """The index of the meaning "that's good, no change" (after the 2F feature meanings)."""
        return 2 * self.num_features

    def meaning_probabilities(self, v: np.ndarray, best: np.ndarray, shown: np.ndarray) -> np.ndarray:
        """(n, C, 2F + 1) P(m | v_s, tau_c) for particles v (n, F) with optima `best` and trajectories `shown` (C,);
        the last meaning is "no change"."""
        cfg = self.cfg
        gap = self.z_pool[best][:, None, :] - self.z[np.asarray(shown)][None, :, :]  # (n, C, F)
        logits = v[:, None, :] * gap / cfg.answer_temperature
        stay = np.full(logits.shape[:2] + (1,), cfg.no_change_logit)
        p = np.exp(_log_softmax(np.concatenate([logits, stay], axis=-1)))
        pf = p[..., :-1]
        up = np.where(v >= 0, 1.0 - cfg.direction_slip, cfg.direction_slip)[:, None, :]  # (n, 1, F) P(increase)
        out = np.empty(pf.shape[:2] + (2 * pf.shape[2] + 1,))
        out[..., 0:-1:2] = pf * up
        out[..., 1:-1:2] = pf * (1.0 - up)
        out[..., -1] = p[..., -1]
        return (1.0 - cfg.lapse) * out + cfg.lapse / out.shape[-1]

    def _log_likelihood(self, v: np.ndarray, best: np.ndarray, answer: tuple) -> np.ndarray:
        """(n,) log-likelihood of one recorded answer under each particle."""
        return reading_of(answer[0]).log_likelihood(self, v, best, answer)

    def _total_log_likelihood(self, v: np.ndarray, best: np.ndarray) -> np.ndarray:
        total = np.zeros(len(v))
        for answer in self.answers:
            total += self._log_likelihood(v, best, answer)
        return total

    # ---- learning ----------------------------------------------------------------------------------------------

    def reading(self, text: str) -> np.ndarray:
        """P(m | text) over the 2F meanings (meaning 2k + d: feature `features[k]`, d = 0 increase)."""
        return np.exp(self.reader.log_probabilities(self.space.psi_of(text)))

    def meaning_index(self, feature: int, direction: int) -> int:
        """The answer model's index of (dataset feature index, direction 0 increase / 1 decrease)."""
        position = np.flatnonzero(self.features == int(feature))
        if len(position) == 0:
            raise LangprefError(f"feature {feature} has no phrasings in the bank, so no meaning of the answer model")
        return 2 * int(position[0]) + int(direction)

    def observe(self, kind: str, answer: Any, meaning: int | None = None) -> None:
        """Record an answer of `kind` (a kind with a reading, `reading_of`); `fit` folds it into the belief. For a
        kind that can be confirmed, `meaning` (`meaning_index`), when the person confirmed what they meant, replaces
        the model's reading."""
        self._pending.append((kind, *reading_of(kind).record(self, answer, meaning)))

    def fit(self) -> None:
        """Reweight the particles by every answer observed since the last fit; resample and move them when the
        effective sample size falls below half."""
        for answer in self._pending:
            self.log_weights += self._log_likelihood(self.v, self.best, answer)
            self.answers.append(answer)
            self.log_weights -= self.log_weights.max()
            if self.effective_sample_size() < 0.5 * len(self.v):
                self._resample_move()
        self._pending = []

    def weights(self) -> np.ndarray:
        w = np.exp(self.log_weights - self.log_weights.max())
        return w / w.sum()

    def effective_sample_size(self) -> float:
        w = self.weights()
        return float(1.0 / np.sum(w * w))

    def _resample(self, n: int, rng: np.random.Generator | None = None) -> np.ndarray:
        """n particle indices, systematic resampling by weight (from `rng`, default the learner's own)."""
        positions = ((self.rng if rng is None else rng).random() + np.arange(n)) / n
        return np.minimum(np.searchsorted(np.cumsum(self.weights()), positions), len(self.v) - 1)

    def _resample_move(self) -> None:
        idx = self._resample(len(self.v))
        v, best = self.v[idx], self.best[idx]
        log_post = self._total_log_likelihood(v, best) - 0.5 * np.sum(v * v, axis=1) / self.cfg.prior_scale**2
        step = 0.5 * np.maximum(v.std(axis=0), 0.02 * self.cfg.prior_scale)
        for _ in range(self.cfg.move_steps):
            proposal = v + step * self.rng.standard_normal(v.shape)
            best_p = self._best(proposal)
            log_p = (
                self._total_log_likelihood(proposal, best_p)
                - 0.5 * np.sum(proposal * proposal, axis=1) / self.cfg.prior_scale**2
            )
            accept = np.log(self.rng.random(len(v))) < log_p - log_post
            v = np.where(accept[:, None], proposal, v)
            best = np.where(accept, best_p, best)
            log_post = np.where(accept, log_p, log_post)
        self.v, self.best = v, best
        self.log_weights = np.zeros(len(v))

    # ---- what it learned ---------------------------------------------------------------------------------------

    def mean(self) -> np.ndarray:
        """The posterior mean of v (F,)."""
        return self.weights() @ self.v

    def latent_weights(self) -> np.ndarray:
        """The posterior-mean reward as a linear reward on phi: xi (D,) with xi . phi = r + a constant."""
        return (self.mean() / self.sd) @ self.axes

    def predict(self, phi: np.ndarray) -> np.ndarray:
        """The posterior-mean reward of each row of `phi` (latent points: dataset or generated trajectories)."""
        z = (np.asarray(phi, dtype=np.float64) @ self.axes.T - self.mu) / self.sd
        return z @ self.mean()

    def draw(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """n draws of the belief (v (n, F), their optima in the pool (n,)), resampled by weight with `rng` (the
        selection's stream, so that choosing a query leaves the belief's own stream untouched)."""
        idx = self._resample(int(n), rng)
        return self.v[idx], self.best[idx]

    def language_gains(self, v: np.ndarray, best: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """I(v; reading | tau) in nats for each of `rows`, from draws (v, best): the information in the meaning the
        model will read, through the reader's confusion of meanings (`AnswerReader.confusion`)."""
        return mutual_information(self.meaning_probabilities(v, best, rows) @ self.reader.confusion)

    def comparison_gains(self, v: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(i, j, I(v; choice) in nats) over the pairs i < j of `rows` (positions in rows), from draws v."""
        r = self.cfg.comparison_rationality * (self.z[rows] @ v.T).astype(np.float32)  # (C, S)
        i, j = np.triu_indices(len(rows), k=1)
        return i, j, binary_mutual_information(0.5 * (1.0 + np.tanh(0.5 * (r[i] - r[j]))))

    def credible(self, v_true: np.ndarray, level: float = 0.9) -> bool:
        """Whether the direction of `v_true` lies in the belief's `level` credible region of directions (the
        particles' cosines to the posterior-mean direction, weighted): for calibration checks."""
        u = _unit(self.v)
        centre = _unit(self.weights() @ u)
        cos = u @ centre
        order = np.argsort(-cos)
        at = min(int(np.searchsorted(np.cumsum(self.weights()[order]), level)), len(order) - 1)
        cutoff = cos[order][at]
        return bool(_unit(np.asarray(v_true, dtype=np.float64)) @ centre >= cutoff)


class AnswerModelInfoGain(Selector):
    """`infogain` under the answer model: I(v; answer | query) from draws of the learner's belief, for language
    queries, comparisons, or both per modelled second (`costs`, a mixed learner)."""

    name = "infogain"

    def __init__(
        self,
        space: LatentSpace,
        pool: Sequence[int],
        kinds: Sequence[str],
        costs: Mapping[str, float] | None = None,
        candidates: int | None = None,
        samples: int = 64,
    ):
        for kind in kinds:
            reading_of(kind)  # a one-line error for a kind it cannot read
        self.space = space
        self.pool = np.asarray(pool, dtype=np.int64)
        self.kinds = tuple(kinds)
        self.costs = dict(costs or {})
        self.candidates = candidates
        self.samples = int(samples)

    def score(self, learner: AnswerModelLearner, rng: np.random.Generator) -> Scored:
        rows = candidate_rows(self.pool, self.candidates, rng)
        v, best = learner.draw(self.samples, rng)
        phi = self.space.phi[rows]
        parts = [reading_of(k).candidates(learner, v, best, rows, phi) for k in self.kinds]
        return parts[0] if len(parts) == 1 else join(parts, self.costs)
