"""The reward-learning loop (`langpref learn-reward`): a synthetic human answers Q queries, the learner
(`langpref.reward.learner` for `--learner paper`, `langpref.reward.answer_model` for `--learner answer-model`) is
refit after each, and the metrics (`langpref.reward.metrics`) are recorded after every query.

Queries are drawn uniformly from the query split (the paper's), or chosen by an active strategy from the learner's
Laplace posterior (`query_selection`; `langpref.reward.selection`, `langpref.reward.posterior`) from a separate
random stream, so that the human's answers and the negatives draw from the same streams whatever the strategy. With
`feedback="mixed"` one learner asks either kind, each query of the kind and item with the most information per
modelled second of the person's time (`langpref.reward.mixed`, `langpref.reward.cost`), and its answers, of both
kinds, enter the same fit. With `query_batch` K > 1, K queries are chosen at once (`langpref.reward.batch`) and the
learner is refit only after the K-th answer; the metrics are still recorded after every query, so within a batch the
curves stay where the last refit left them.

Metrics (Sec. 5.1), on an evaluation split: `cross_entropy(P_w, P_xi)` averaged over all its unordered pairs, and
`reward_of_best`, the normalised true reward (0 worst, 1 best of the split) of the trajectory r_xi ranks first
(averaged over ties, so a constant r_xi scores the split's mean). Beside them, the metrics reward models are compared
by elsewhere (`langpref.reward.metrics`): `kendall_tau` between the true and the learned ranking of the evaluation
split and `epic_distance` between the two rewards over every trajectory of the dataset, after every query; and with
per-step embeddings of the evaluation split's successful episodes (`langpref.reward.steps.success_prefixes`),
`value_order`, the value-order correlation of r_xi through them after the last query.

Beyond the dataset (`learn-reward --optimize`, `langpref.propose`): after the last query, r_xi's own optimum is
generated in the simulator (CMA-ES on a surrogate of phi, decided by r_xi of real rollouts embedded by the real
encoder) and `optimized_true_reward` is its true reward on the same scale, so above 1 is better than any trajectory of
the eval split. `--save-reward DIR` writes each run's r_xi for `langpref.reward.saved.LearnedReward`.
"""

from __future__ import annotations

import sys
from dataclasses import asdict, dataclass, field

import numpy as np

from langpref.dataset.splits import Split
from langpref.errors import LangprefError
from langpref.feedback.humans import HumanConfig, normalised_reward, sample_weights, true_reward
from langpref.feedback.kind import MIXED, FeedbackKind, get_kind, kind_names, kind_of, mixed_kinds, random_query
from langpref.feedback.space import LatentSpace
from langpref.reward.answer_model import AnswerModelConfig, AnswerModelLearner
from langpref.reward.cost import query_costs
from langpref.reward.curves import Curves, summarise_curves
from langpref.reward.learner import RewardConfig, RewardLearner
from langpref.reward.learners import get_learner, learner_names, paper_selector
from langpref.reward.metrics import value_order_correlation
from langpref.reward.steps import SuccessEpisodes


def feedback_choices() -> tuple[str, ...]:
    """Every `feedback` a learner takes: each registered kind (an installed plugin's too), and `mixed` (language and
    comparisons, chosen per query)."""
    return (*kind_names(), MIXED)


# ---- simulated sessions (`langpref learn-reward`) -----------------------------------------------------------------


@dataclass
class LearnRewardConfig:
    """`langpref learn-reward`: synthetic humans x seeds, Q queries each, metrics after every query."""

    feedback: str = "language"
    """The kind of feedback (`langpref.feedback.KINDS`). `language` (one trajectory shown, comparative feedback),
    `comparison` (a pair shown, one choice), any registered kind, or `mixed`: both in one learner, each query of the
    kind and item with the most information per modelled second (`infogain`; the linear reward)."""
    queries: int = 40
    """Q, queries per run."""
    humans: int = 3
    """Synthetic humans (reward weights w), drawn from `seed`."""
    seeds: int = 3
    """Runs per human (query draws, answer noise, negatives)."""
    seed: int = 0
    """Master seed: the same seed gives the same numbers."""
    query_split: Split = "train"
    """Trajectories shown in queries; the language human's tau* is the best of this split."""
    eval_split: Split = "test"
    """Split of the metrics. On another split than test, the humans and run seeds come from another stream of `seed`
    (`human_stream`): what is chosen on val is chosen with other humans than the test runs'."""
    human: HumanConfig = field(default_factory=HumanConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    learner: str = "paper"
    """A registered learner (`langpref.reward.learners`; an installed package adds its own). `paper`: Eq. 5-9's
    Bradley-Terry pairs fit by `reward` (`langpref.reward.learner`, the reproduction);
    `answer-model`: a belief over the reward whose likelihood of a sentence depends on the trajectory it was said
    about, with comparisons in the same belief (`langpref.reward.answer_model`; `random` or `infogain` queries)."""
    answer_model: AnswerModelConfig = field(default_factory=AnswerModelConfig)
    confirm_margin: float | None = None
    """Ask when unsure (answer-model learner, language): when the top two of the model's reading of a sentence are
    closer than this in probability, the person confirms what they meant with one click among the model's top 3
    readings or "none of these" (then the answer is not learned from). None: never ask (the paper's protocol)."""
    confirm_seconds: float = 0.3
    """Modelled time of one confirmation click, in the unit of `comparison_seconds` (an assumption: one click
    among four labelled buttons, against watching two videos and choosing)."""
    query_selection: str | None = None
    """How each query is chosen (`langpref.reward.selection`): None or `random` (uniform, the paper's); `infogain`
    (language and comparisons: information about the reward, Laplace posterior); `lal-infogain` (language: the
    authors' follow-up); `volume-removal` (comparisons). Active strategies need the linear reward model."""
    candidates: int | None = None
    """Active strategies score a random subset of this many trajectories of the query split, drawn afresh for
    every query; None: the whole split."""
    posterior_samples: int | None = None
    """Draws of the reward's Laplace posterior per active selection; None: 64."""
    query_batch: int | None = None
    """K, queries chosen at once (greedily, by score with a penalty for pointing the same way in the latent space as
    one already in the batch); the learner is refit only after the batch. None: 1, a refit after every query."""
    language_seconds: float | None = None
    """Modelled time a person takes per language query, in the unit of comparison_seconds. None: 0.887, the paper's
    measurement (Sec. 5.2: language took 11.3% less time per query than comparisons; it gives no seconds). Sets
    what `mixed` asks and the time axis of the curves."""
    comparison_seconds: float | None = None
    """Modelled time a person takes per comparison. None: 1.0 (the unit; the paper reports only the ratio); give
    both in seconds where they were measured."""

    @property
    def selection(self) -> str:
        """The query selection strategy: `random` when unset (`infogain` for `mixed`)."""
        return self.query_selection or ("infogain" if self.feedback == MIXED else "random")

    @property
    def batch(self) -> int:
        """K, queries chosen at once (1 when unset)."""
        return 1 if self.query_batch is None else int(self.query_batch)

    @property
    def spoken_phrasings(self) -> str:
        """The phrase table the synthetic language human speaks from (`HumanConfig.phrase_source`)."""
        return self.human.phrase_source

    @property
    def costs(self) -> dict[str, float]:
        """Modelled seconds per query by kind (`langpref.reward.cost.query_costs`)."""
        return query_costs({"language": self.language_seconds, "comparison": self.comparison_seconds})

    def validate(self) -> None:
        from langpref.reward.posterior import require_linear
        from langpref.reward.selection import check_strategy

        if self.feedback not in feedback_choices():
            raise LangprefError(f"unknown feedback {self.feedback!r}: choose one of {', '.join(feedback_choices())}")
        if self.learner not in learner_names():
            raise LangprefError(f"unknown learner {self.learner!r}: choose one of {', '.join(learner_names())}")
        learner = get_learner(self.learner)
        asks = learner.selections
        if asks is not None and self.selection not in asks:
            raise LangprefError(
                f"the {self.learner} learner asks with {' or '.join(asks)} queries, not {self.selection!r}"
            )
        if learner.check is not None:
            learner.check(self)
        if self.confirm_margin is not None and (learner.confirm is None or not 0 <= self.confirm_margin <= 1):
            raise LangprefError("--confirm-margin takes a value in [0, 1] and needs a learner that asks to confirm")
        if self.confirm_seconds < 0:
            raise LangprefError(f"confirm_seconds must be >= 0, got {self.confirm_seconds}")
        check_strategy(self.selection, self.feedback)
        if self.query_batch is not None and self.query_batch < 1:
            raise LangprefError(f"query_batch must be >= 1, got {self.query_batch}")
        self.costs  # noqa: B018 (checks the seconds)
        require_linear(self.reward.model, self.selection)
        if self.candidates is not None and self.candidates < 2:
            raise LangprefError(f"candidates must be >= 2, got {self.candidates}")
        if self.posterior_samples is not None and self.posterior_samples < 2:
            raise LangprefError(f"posterior_samples must be >= 2, got {self.posterior_samples}")
        if self.queries < 1 or self.humans < 1 or self.seeds < 1:
            raise LangprefError("queries, humans and seeds must each be >= 1")
        self.human.validate()
        self.reward.validate()


NEWER_HUMAN_FIELDS = {"feature_rule": "eq10", "vague": 0.0, "no_change_logit": None, "no_change_margin": None}
"""Fields of the synthetic human added with the answer-model learner, and their defaults."""


def config_record(cfg: LearnRewardConfig) -> dict:
    """The config as written into results. Fields added with the answer-model learner are left out while they hold
    their defaults (the paper's learner, the Eq. 10 human), so that the paper's output stays what it was before that
    learner existed, byte for byte (tests/reward/test_answer_model.py pins it)."""
    record = asdict(cfg)
    if cfg.learner == LearnRewardConfig.learner:  # the default learner's record is as before learners were parts
        del record["learner"]
    own = get_learner(cfg.learner).own_config
    for name in {t.own_config for t in map(get_learner, learner_names())} - {own, None}:
        del record[name]
    if cfg.confirm_margin is None:
        del record["confirm_margin"], record["confirm_seconds"]
    for name, default in NEWER_HUMAN_FIELDS.items():
        if record["human"][name] == default:
            del record["human"][name]
    return record


SPLIT_STREAMS = {"val": 0x76616C, "train": 0x747261}
"""Tags of the seed streams of runs scored on another split than test (the bytes of "val", "tra")."""


def human_stream(seed: int, eval_split: str = "test") -> tuple[int, ...]:
    """The seed stream of master seed `seed`'s synthetic humans and run seeds, for runs scored on `eval_split`:
    `(seed,)` on test (the experiments' humans, unchanged), `(seed, tag)` on val or train. So a choice made on val
    (a prior scale, a no-change logit) never meets a test human or a test run's draws, whatever `--seed` it is
    given: the streams differ in length, and no test seed gives a val stream."""
    return (int(seed),) if eval_split == "test" else (int(seed), SPLIT_STREAMS[eval_split])


def human_weights(num_features: int, seed: int | tuple[int, ...], human: int) -> np.ndarray:
    """The reward weights of synthetic human number `human` of experiment seed `seed` (an int: the test stream), or
    of the seed stream `seed` (`human_stream`)."""
    stream = (seed,) if isinstance(seed, int | np.integer) else tuple(seed)
    return sample_weights(num_features, np.random.default_rng([*stream, 7919, human]))


def run_reward_learning(
    space: LatentSpace,
    w: np.ndarray,
    cfg: LearnRewardConfig,
    run_seed: tuple[int, ...],
    record: list | None = None,
    generation=None,
    learners: list | None = None,
    episodes: SuccessEpisodes | None = None,
) -> Curves:
    """One run: Q queries of `cfg.feedback` to the synthetic human with weights `w`; metrics after each. Queries
    are drawn uniformly (`random`, from their own stream) or chosen by `cfg.query_selection` (from another stream,
    so the human's answers and the negatives use the same streams whatever the strategy), `cfg.batch` at a time,
    the learner refit after each batch. `mixed` asks a language human and a comparison human with the same `w`,
    each on the answer stream of its kind's single-kind runs, so a mixed run that asks one kind only is that kind's
    `infogain` run, answer for answer. With `record`, appends each query's `langpref.reward.selection.Selection`
    (score None for random) and answer as a pair. With `generation` (`langpref.propose.Generation`), generates r_xi's
    optimum after the last query and scores it (`Curves.optimized_true_reward`); with `learners`, appends the final
    reward model; with `episodes` (successful episodes step by step, `langpref.reward.steps`), scores the final
    r_xi's value-order correlation through them, and the true reward's (`Curves.value_order`, `value_order_true`)."""
    cfg.validate()
    pool = space.split(cfg.query_split)
    eval_rows = space.split(cfg.eval_split)
    R_eval = true_reward(w, space.theta[eval_rows])
    R_all = true_reward(w, space.theta)
    rng_query, rng_human, rng_neg = (np.random.default_rng([*run_seed, k]) for k in (1, 2, 3))
    learner_seed = int(np.random.default_rng([*run_seed, 4]).integers(2**31))
    learner = _make_learner(cfg, space, pool, learner_seed)
    selector = _selector(cfg, space, pool)
    rng_select = np.random.default_rng([*run_seed, 5])
    costs = cfg.costs
    curves = Curves(seconds=[0.0])
    curves.record(learner, space, eval_rows, R_eval, cfg.human.rationality, R_all)
    humans = _make_humans(cfg, w, space, pool, run_seed, rng_human)
    while len(curves.kinds) < cfg.queries:
        size = min(cfg.batch, cfg.queries - len(curves.kinds))
        batch = (
            _random_batch(get_kind(cfg.feedback), pool, rng_query, size)
            if selector is None
            else selector.select_batch(learner, rng_select, size)
        )
        for n, chosen in enumerate(batch, start=1):
            kind = kind_of(chosen.query)
            answer = humans[kind.name].answer(chosen.query)
            if selector is not None:
                selector.observe(space, answer)
            if record is not None:
                record.append((chosen, answer))
            seconds = costs.get(kind.name, 1.0)
            seconds += _learn_from(learner, kind, answer, cfg, space, rng_neg, curves)
            if n == len(batch):
                learner.fit()
            curves.kinds.append(kind.name)
            curves.no_change += [len(curves.kinds)] if getattr(answer, "no_change", False) else []
            curves.seconds.append(curves.seconds[-1] + seconds)
            curves.record(learner, space, eval_rows, R_eval, cfg.human.rationality, R_all)
    _score_final(curves, learner, space, w, cfg, R_eval, run_seed, generation, episodes)
    if learners is not None:
        learners.append(learner)
    return curves


def _make_learner(
    cfg: LearnRewardConfig, space: LatentSpace, pool: np.ndarray, seed: int
) -> RewardLearner | AnswerModelLearner:
    """The learner of `cfg.learner` (`langpref.reward.learners`)."""
    return get_learner(cfg.learner).make(space, pool, cfg, seed)


def _make_humans(
    cfg: LearnRewardConfig,
    w: np.ndarray,
    space: LatentSpace,
    pool: np.ndarray,
    run_seed: tuple[int, ...],
    rng_human: np.random.Generator,
) -> dict:
    """kind name -> the synthetic human with weights `w` who answers queries of that kind. `mixed` puts each kind's
    human on the stream of that kind's own runs (common random numbers)."""
    if cfg.feedback == MIXED:
        return {
            name: get_kind(name).make_human(w, space, pool, cfg.human, np.random.default_rng([*run_seed, 2]))
            for name in mixed_kinds()
        }
    return {cfg.feedback: get_kind(cfg.feedback).make_human(w, space, pool, cfg.human, rng_human)}


def _learn_from(
    learner: RewardLearner | AnswerModelLearner,
    kind: FeedbackKind,
    answer,
    cfg: LearnRewardConfig,
    space: LatentSpace,
    rng_neg: np.random.Generator,
    curves: Curves,
) -> float:
    """Give `answer` to the learner (not fit yet); the extra modelled seconds it cost (a confirmation asked of the
    person, with `confirm_margin` and a learner that asks, `LearnerType.confirm`)."""
    learner_type = get_learner(cfg.learner)
    asks = cfg.confirm_margin is not None and learner_type.confirm is not None
    confirmed = learner_type.confirm(learner, kind, answer, cfg.confirm_margin) if asks else None
    if confirmed is None:
        learner_type.teach(learner, space, kind, answer, cfg, rng_neg)
        return 0.0
    asked, meaning = confirmed
    curves.confirmed.append(-1 if not asked else (2 * meaning[0] + meaning[1] if meaning is not None else -2))
    if not (asked and meaning is None):  # "none of these": stored, not learned from
        learner_type.teach(learner, space, kind, answer, cfg, rng_neg, meaning)
    return cfg.confirm_seconds if asked else 0.0


def _score_final(
    curves: Curves,
    learner: RewardLearner | AnswerModelLearner,
    space: LatentSpace,
    w: np.ndarray,
    cfg: LearnRewardConfig,
    R_eval: np.ndarray,
    run_seed: tuple[int, ...],
    generation,
    episodes: SuccessEpisodes | None,
) -> None:
    """What is scored once, after the last query: the answer-model belief's calibration, r_xi's generated optimum
    (with `generation`) beside its best recorded trajectory over every split (the baseline the optimum, which starts
    from and is fitted on all of them, must beat), and the value-order correlations through successful episodes
    (with `episodes`)."""
    credible = get_learner(cfg.learner).credible
    if credible is not None:
        curves.credible = credible(learner, w)  # the experimenter's check
    if generation is not None:
        best = optimize_reward(generation, learner, run_seed).trajectories[0]
        raw = true_reward(w, generation.theta(best)[None])  # the experimenter scores it; the proposer never does
        curves.optimized_true_reward = float(normalised_reward(raw, R_eval)[0])
        recorded = int(np.argmax(learner.predict(space.phi)))
        curves.recorded_true_reward = float(normalised_reward(true_reward(w, space.theta[[recorded]]), R_eval)[0])
    if episodes is not None:
        order = value_order_correlation([learner.predict(np.ascontiguousarray(p)) for p in episodes.phi])
        truth = value_order_correlation([true_reward(w, t) for t in episodes.theta])
        curves.value_order, curves.value_order_true = (None if np.isnan(v) else v for v in (order, truth))


def _selector(cfg: LearnRewardConfig, space: LatentSpace, pool: np.ndarray):
    """The active strategy of `cfg` (None for random: the loop draws uniformly): the learner's own
    (`LearnerType.selector`), else the paper's learner's (`langpref.reward.learners.paper_selector`)."""
    return (get_learner(cfg.learner).selector or paper_selector)(cfg, space, pool)


def _random_batch(kind: FeedbackKind, pool: np.ndarray, rng: np.random.Generator, size: int) -> list:
    """`size` uniform queries of `kind`, one after another from the query stream (a batch of 1 is the paper's)."""
    from langpref.reward.selection import Selection

    return [Selection(random_query(kind, pool, rng), None, "random", len(pool)) for _ in range(size)]


def optimize_reward(generation, learner: RewardLearner, run_seed: tuple[int, ...] = (0,)):
    """r_xi's optimum made in the simulator (`langpref.propose.Proposer.optimise`), starting from the dataset
    trajectory r_xi ranks first; the `Proposal` of every rollout, best first by r_xi."""
    start = generation.units[int(np.argmax(learner.predict(generation.phi)))]
    return generation.proposer(key=(*run_seed, 31337)).optimise(learner.predict, start)


def _save_run_reward(learner, directory: str, space: LatentSpace, model: str | None, name: str, default: bool) -> str:
    """Write one run's r_xi into `directory` (`langpref.reward.saved`), with what it wants in the task's features;
    its path."""
    from langpref.reward.saved import save_learned_reward

    saved = save_learned_reward(learner, directory, env=space.env, model=model, name=name, default=default, space=space)
    return str(saved)


def learn_reward(
    space: LatentSpace,
    cfg: LearnRewardConfig,
    progress: bool = True,
    generation=None,
    save_reward: str | None = None,
    model: str | None = None,
    episodes: SuccessEpisodes | None = None,
) -> dict:
    """cfg.humans x cfg.seeds runs on `space`; the summary of `summarise_curves` plus the config. With `generation`
    (`langpref.propose.Generation`), each run also generates r_xi's optimum (`optimized_true_reward`, one per run);
    with `save_reward` (a directory), each run's r_xi is written there for `langpref.reward.saved.LearnedReward`, beside
    a reference to the checkpoint `model` whose trajectory encoder it reads. With `episodes` (the evaluation split's
    successful episodes step by step, `langpref.reward.steps.success_prefixes`), each run's final r_xi is scored by
    its value-order correlation through them, beside the true reward's (`value_order_correlation`)."""
    from tqdm import tqdm

    cfg.validate()
    if save_reward:
        from langpref.reward.saved import check_saveable

        check_saveable(model)
    runs, saved = [], []
    with tqdm(
        total=cfg.humans * cfg.seeds,
        desc=f"learn-reward {cfg.feedback} {cfg.selection}",
        disable=not progress,
        file=sys.stderr,
    ) as bar:
        stream = human_stream(cfg.seed, cfg.eval_split)
        for h in range(cfg.humans):
            w = human_weights(len(space.feature_names), stream, h)
            for s in range(cfg.seeds):
                learners = [] if save_reward else None
                runs.append(
                    run_reward_learning(
                        space, w, cfg, (*stream, h, s), generation=generation, learners=learners, episodes=episodes
                    )
                )
                if save_reward:
                    saved.append(_save_run_reward(learners[0], save_reward, space, model, f"h{h}-s{s}", not saved))
                bar.update()
    extra = {"saved_rewards": saved} if saved else {}
    if generation is not None:
        extra["propose"] = asdict(generation.cfg)
    return {
        **summarise_curves(runs),
        "feedback": cfg.feedback,
        "loss": cfg.reward.loss,
        "query_selection": cfg.selection,
        "config": config_record(cfg),
        "space": space.description,
        **extra,
    }
