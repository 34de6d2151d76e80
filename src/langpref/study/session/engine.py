"""The learning side of the study: a thin adapter over the library for live participants.

- embedding feedback: `model.encode_texts` (psi), cached per text; "how the robot understood it" is
  `langpref.model.evaluate.embed_text` (nearest meaning prototype) on the same psi; text that does not read as
  feedback on the robot's motion is refused first (`langpref.language.relevance.FeedbackGate`);
- the improvement step of Study 1 (paper Eq. 4, its cosine reading: `langpref.improve.improvement_step`) over the
  study set;
- one reward learner per participant and method (`StudyConfig.learner`, `langpref.study.session.learners`): the paper's
  (`langpref.reward.RewardLearner`, fed by the method's feedback kind: its `pairs`, explicit + implicit losses for
  language, Bradley-Terry for comparisons) or the answer-model learner, refit after every answer; a language answer
  whose meaning the participant confirmed (`--confirm-margin`) teaches that meaning;
- which trajectories each query shows (`langpref.study.protocol.queries`: random, as in the paper, or an active strategy
  of `langpref.reward.selection` over the participant's learner; fixed by the study and participant seeds).

The database is the only state that counts: a learner lost with a restart is rebuilt by replaying the participant's
stored answers (`history`), with the same seeds, so it learns what it had learned.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import replace
from functools import cached_property
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from langpref.errors import LangprefError
from langpref.feedback.kind import FeedbackKind, get_kind
from langpref.improve import improvement_step
from langpref.language.coalesce import REMEMBERED, Coalesced
from langpref.language.relevance import FeedbackGate
from langpref.reward import RewardConfig, RewardLearner
from langpref.reward.answer_model import CONFIRM_OPTIONS, AnswerModelConfig, AnswerModelLearner
from langpref.reward.learners import LearnerSettings, get_learner
from langpref.study.protocol.config import StudyConfig
from langpref.study.protocol.flow import Confirmed, Participant
from langpref.study.protocol.kinds import said
from langpref.study.protocol.queries import Chosen, QueryChooser
from langpref.study.session.learners import Meanings, learned_reward

History = Callable[[str, str], list[Any]]
"""(participant id, method) -> the participant's stored answers of that method, in order, as the kind's answers."""
Confirmations = Callable[[str, str], dict[int, Confirmed]]
"""(participant id, method) -> {query number: what the participant confirmed its answer meant}."""
Learner = RewardLearner | AnswerModelLearner


class Candidates(Protocol):
    """Study 1's generated candidates as the robot uses them (`langpref.study.session.generated.Generator`, which is
    built over a `StudyEngine` and so stands above this module): the id of the trajectory made for a round, and phi
    of a trajectory (NotReady while it is being made)."""

    def id_for(self, p: Participant, round_: int) -> int: ...

    def phi(self, index: int) -> np.ndarray: ...


NO_CHANGE_READING: dict[str, Any] = {"feature": None, "direction": None, "confidence": 1.0, "no_change": True}
"""How "that's good, no change" (a button, never read by the model) is shown back and stored."""


class _TextCache(Coalesced):
    """psi of texts (the model's language encoder), shared by the reward learner and `embed_text`: the last 4096
    texts remembered, the new texts of answers that arrive together read in one pass (`langpref.language.coalesce`;
    one text alone costs about as much as eight in a batch)."""

    def __init__(self, model, size: int = REMEMBERED):
        super().__init__(self._encode, remember=size)
        self.model = model

    def _encode(self, texts: list[str]) -> np.ndarray:
        return self.model.encode_texts(texts).detach().cpu().numpy().astype(np.float64)


class _CachedModel:
    """The model as `embed_text` sees it, with `encode_texts` answered from the cache."""

    def __init__(self, model, cache: _TextCache):
        self._model = model
        self._cache = cache

    def encode_texts(self, texts):
        import torch

        return torch.from_numpy(self._cache(list(texts)))

    def __getattr__(self, name: str):
        return getattr(self._model, name)


class StudyEngine:
    """Model, dataset and latent space of a study, shared by all participants (read-only after construction)."""

    def __init__(self, model, dataset, cfg: StudyConfig):
        from langpref.feedback.space import build_latent_space

        cfg.validate()
        self.model = model
        self.dataset = dataset
        self.cfg = cfg
        self.reward_cfg = RewardConfig(num_negatives=cfg.num_negatives)
        self.reward_cfg.validate()
        self.cache = _TextCache(model)
        space = build_latent_space(model, dataset, bank_splits=(self.reward_cfg.negative_split,))
        self.space = replace(space, encode=self.cache)
        self.study = np.asarray(range(len(dataset)) if cfg.split == "all" else dataset.split(cfg.split), dtype=np.int64)
        if len(self.study) < 2:
            raise LangprefError(
                f"split {cfg.split!r} of {dataset.root} has {len(self.study)} trajectories; a study "
                "needs at least 2 (pass another --split)"
            )
        success = np.asarray(dataset.success)[self.study]
        self.failed = self.study[~success] if (~success).any() else self.study
        self._understanding = _CachedModel(model, self.cache)
        self.gate = FeedbackGate(self.env)
        self.understand("Move faster.")  # fail at start, not with the first participant, if prototypes are missing
        _ = self.gate.scope_check  # built (and its corpus embedded) now, not on the first answer
        self._read_bank(space)

    def _read_bank(self, space) -> None:
        """psi of every phrasing of the bank remembered now, in a few batched passes (those of the negative split
        are the space's own): a participant who types one costs no pass of the model's encoder."""
        known = set()
        for table in space.phrases.values():
            texts = [self.normalise(t) for t in table.texts]
            self.cache.keep(texts, np.asarray(table.psi, dtype=np.float64))
            known.update(texts)
        self.cache(sorted({self.normalise(t) for t in self.gate.phrasings} - known))

    @classmethod
    def load(cls, model_dir: str | Path, data_dir: str | Path, cfg: StudyConfig) -> StudyEngine:
        from langpref.dataset.storage import load_dataset
        from langpref.model.checkpoint import load_model

        dataset = load_dataset(data_dir)
        return cls(load_model(model_dir, device="cpu", dataset=dataset), dataset, cfg)

    @cached_property
    def settings(self) -> LearnerSettings:
        """The learners' settings: the study's reward settings; the answer-model learner's T_read as the engine
        fitted it once (the same fit the learner would make)."""
        return LearnerSettings(self.reward_cfg, AnswerModelConfig(reading_temperature=self.meanings.temperature))

    @cached_property
    def meanings(self) -> Meanings:
        """The model's reading of a sentence over the bank's meanings (made when first needed: the answer-model
        learner, `--confirm-margin`)."""
        return Meanings(self.space, self.reward_cfg.negative_split)

    @property
    def env(self) -> str:
        return self.dataset.env

    @staticmethod
    def normalise(text: str) -> str:
        return " ".join(str(text).split())

    def understand(self, text: str) -> dict[str, Any]:
        """How the model reads `text`: nearest (feature, direction) and its confidence (`embed_text`)."""
        from langpref.model.evaluate import embed_text

        out = embed_text(self._understanding, self.normalise(text))
        return {"feature": out["feature"], "direction": out["direction"], "confidence": round(out["confidence"], 4)}

    def psi(self, text: str) -> np.ndarray:
        return self.cache([self.normalise(text)])[0]

    def improve(self, current: int, text: str) -> int:
        """Eq. 4 over the study set (the current trajectory included: it stays when nothing moves along psi)."""
        phi = self.space.phi
        return int(self.study[improvement_step(phi[self.study], phi[current], self.psi(text))])

    def describe(self) -> dict[str, Any]:
        return {
            "env": self.env,
            "data": str(self.dataset.root),
            "num_trajectories": len(self.dataset),
            "split": self.cfg.split,
            "study_set": self.study.tolist(),
            "latent_dim": self.space.dim,
        }


class StudyRobot:
    """The `flow.Robot` of a running study: per-participant reward learners over a shared `StudyEngine`. `cfg` is the
    study's protocol (default the engine's): its seed, query selection and learner; `generated`, Study 1's generated
    candidates (`--improve-candidates generated`); `confirmations`, what participants confirmed their language
    answers meant (none by default)."""

    def __init__(
        self,
        engine: StudyEngine,
        history: History,
        max_cached: int = 512,
        cfg: StudyConfig | None = None,
        generated: Candidates | None = None,
        confirmations: Confirmations | None = None,
    ):
        self.engine = engine
        self.generated = generated
        self.cfg = cfg or engine.cfg
        self.history = history
        self.confirmations = confirmations or (lambda pid, method: {})
        self.max_cached = max_cached
        # (participant, method) -> (learner, answers it has seen, those answers)
        self._learners: OrderedDict[tuple[str, str], tuple[Learner, int, tuple]] = OrderedDict()
        self._lock = threading.Lock()
        self.chooser = QueryChooser(engine.space, engine.study, self.cfg, engine.reward_cfg)

    # ---- which trajectories are shown (fixed by the seeds) ----

    def _rng(self, p: Participant, *keys: int) -> np.random.Generator:
        return np.random.default_rng([self.cfg.seed, p.seed, *keys])

    def start_trajectory(self, p: Participant) -> int:
        """Study 1 starts from a random trajectory that fails the task (any, if none fails)."""
        return int(self._rng(p, 0).choice(self.engine.failed))

    def query(self, p: Participant, method: str, number: int) -> Chosen:
        """What query `number` (1-based) of `method` shows, and why (`langpref.study.protocol.queries`); an active
        strategy reads the learner that has seen the first `number - 1` answers."""
        return self.chooser.choose(
            method,
            number,
            lambda *keys: self._rng(p, *keys),
            lambda: self._learner(p, method, number - 1),
            lambda: [self.as_read(get_kind(method), answer) for answer in self._answers(p, method, number - 1)],
        )

    def as_read(self, kind: FeedbackKind, answer: Any) -> Any:
        """`answer` as the learners read it: a typed sentence (`FeedbackKind.sentence`) with its whitespace collapsed,
        as the text cache keys it."""
        if kind.sentence is None:
            return answer
        return replace(answer, **{kind.sentence: self.engine.normalise(getattr(answer, kind.sentence))})

    # ---- Study 1 ----

    def improve(self, p: Participant, shown: int, text: str, round_: int) -> tuple[int, dict[str, Any]]:
        """Round `round_` of Study 1: Eq. 4 over the study set, or (generated candidates) the id of the trajectory
        the simulator will make for it (`langpref.study.session.generated`; NotReady while `shown` is being made)."""
        if self.generated is None:
            return self.engine.improve(shown, text), self.engine.understand(text)
        self.generated.phi(shown)
        return self.generated.id_for(p, round_), self.engine.understand(text)

    # ---- Study 2: reward learning ----

    def _fresh(self, p: Participant, method: str) -> Learner:
        seed = int(self._rng(p, 3, self.cfg.kinds.index(method)).integers(2**31))
        return get_learner(self.cfg.learner).make(self.engine.space, self.engine.study, self.engine.settings, seed)

    def _add(
        self, learner: Learner, p: Participant, method: str, number: int, answer: Any, confirmed: Confirmed | None
    ) -> None:
        """Answer `number` of `method` into the learner (`langpref.reward.learners`); language read with its
        whitespace collapsed, as the text cache keys it, or as the meaning the participant `confirmed` ("none of
        these": not learned from). The answer-model learner folds each answer in at once (its resampling depends on
        when it fits); the paper's is fit by the caller, once after a replay (its loss is convex: the same
        minimum)."""
        if confirmed is not None and confirmed.meaning is None:
            return
        meaning = None
        if confirmed is not None:
            m = int(confirmed.meaning)
            meaning = (int(self.engine.meanings.features[m // 2]), m % 2)
        engine, kind, learner_type = self.engine, get_kind(method), get_learner(self.cfg.learner)
        rng = self._rng(p, 4, number)
        learner_type.teach(learner, engine.space, kind, self.as_read(kind, answer), engine.settings, rng, meaning)
        if learner_type.fits_each_answer:
            learner.fit()

    def _learner(self, p: Participant, method: str, answered: int) -> Learner:
        """The learner of (participant, method) that has seen the first `answered` stored answers (kept)."""
        key = (p.id, method)
        with self._lock:
            hit = self._learners.get(key)
        if hit is not None and hit[1] == answered:
            return hit[0]
        learner = self._fresh(p, method)
        past = self.history(p.id, method)[:answered]
        if len(past) != answered:
            raise LangprefError(f"participant {p.id} has {len(past)} stored {method} answers, expected {answered}")
        confirmed = self.confirmations(p.id, method) if past else {}
        for i, answer in enumerate(past, start=1):
            self._add(learner, p, method, i, answer, confirmed.get(i))
        learner.fit()
        self._keep(p, method, learner, past)
        return learner

    def _answers(self, p: Participant, method: str, answered: int) -> list[Any]:
        """The first `answered` answers of (participant, method): those the kept learner has seen (the last may not
        be stored yet: the next query is chosen before its answer is), else the stored ones."""
        with self._lock:
            hit = self._learners.get((p.id, method))
        if hit is not None and hit[1] == answered:
            return list(hit[2])
        return self.history(p.id, method)[:answered]

    def _keep(self, p: Participant, method: str, learner: Learner, past: list[Any]) -> None:
        with self._lock:
            self._learners[(p.id, method)] = (learner, len(past), tuple(past))
            self._learners.move_to_end((p.id, method))
            while len(self._learners) > self.max_cached:
                self._learners.popitem(last=False)

    def learn(
        self, p: Participant, method: str, number: int, answer: Any, confirmed: Confirmed | None = None
    ) -> dict[str, Any] | None:
        """Refit the learner of `method` with answer `number` (read as the meaning the participant `confirmed`, when
        they were asked); how the model read it, for language (else None)."""
        learner = self._learner(p, method, number - 1)
        past = self._answers(p, method, number - 1)
        self._add(learner, p, method, number, answer, confirmed)
        learner.fit()
        self._keep(p, method, learner, [*past, answer])
        kind = get_kind(method)
        if kind.sentence is None:
            return None
        text = said(kind, answer)
        return dict(NO_CHANGE_READING) if text is None else self.engine.understand(text)

    def confirm(self, p: Participant, method: str, answer: Any) -> dict[str, Any] | None:
        """What to ask about a typed answer (language's) whose reading is uncertain (`flow.Robot.confirm`): None
        unless the margin between its top two meanings is below `confirm_margin` (1: always)."""
        limit, text = self.cfg.confirm_margin, said(get_kind(method), answer)
        if limit is None or text is None:
            return None
        meanings = self.engine.meanings
        reading = meanings.reading(self.engine.psi(text))
        margin = meanings.margin(reading)
        if margin >= limit and limit < 1:
            return None
        options = [
            {
                "meaning": m,
                "text": meanings.label(m),
                "feature": meanings.feature(m),
                "direction": meanings.direction(m),
                "p": round(float(reading[m]), 4),
            }
            for m in meanings.top(reading, CONFIRM_OPTIONS)
        ]
        return {"options": options, "margin": round(margin, 4), "understood": self.engine.understand(text)}

    def _current(self, p: Participant, method: str) -> Learner:
        with self._lock:
            hit = self._learners.get((p.id, method))
        return hit[0] if hit is not None else self._learner(p, method, len(self.history(p.id, method)))

    def best(self, p: Participant, method: str) -> int:
        """argmax of the reward learned so far over the study set."""
        reward = self._current(p, method).predict(self.engine.space.phi[self.engine.study])
        return int(self.engine.study[int(np.argmax(reward))])

    def reward(self, p: Participant, method: str) -> dict[str, Any]:
        """The reward learned so far (`langpref.study.session.learners.learned_reward`), as stored after every
        answer."""
        return learned_reward(self._current(p, method), self.engine.space, self.engine.study, self.cfg.learner)

    def forget(self, participant_id: str) -> None:
        """Drop cached learners (after an answer that was not stored): the next use replays the database."""
        with self._lock:
            for method in self.cfg.kinds:
                self._learners.pop((participant_id, method), None)
