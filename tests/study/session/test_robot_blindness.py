"""Blindness of the study robot: what it learns and shows depends on the answers, never on the true features.

Synthetic answers (those a synthetic human with weights w gives, `langpref.study.server.simulate`'s kind) are recorded
once; then a robot whose engine holds scrambled true features (dataset features and the space's theta shuffled among
the trajectories, as a w permuted after the answers were recorded would see them) gets the same answers. Its reward
learners, its best trajectories and its Study-1 moves must be the same bit for bit.
"""

import copy
from dataclasses import replace

import numpy as np

from langpref.feedback import LanguageQuery, get_kind
from langpref.feedback.humans import HumanConfig, sample_weights
from langpref.study.protocol.flow import Participant
from langpref.study.session.engine import StudyRobot


def _scrambled(engine):
    rng = np.random.default_rng(7)
    rows = rng.permutation(len(engine.space.theta))
    cols = rng.permutation(engine.space.theta.shape[1])
    other = copy.copy(engine)
    other.space = replace(engine.space, theta=engine.space.theta[rows][:, cols])
    other.dataset = copy.copy(engine.dataset)
    other.dataset.features = engine.dataset.features[rows][:, cols]
    return other


def test_the_study_robot_is_blind_to_the_true_features(engine):
    p = Participant("p-blind", 1, ("language", "comparison"), 12345)
    w = sample_weights(len(engine.space.feature_names), 3)
    history: dict[str, list] = {"language": [], "comparison": []}
    robot = StudyRobot(engine, lambda pid, method: history[method])
    answers = {}
    for method in ("language", "comparison"):
        kind = get_kind(method)
        human = kind.make_human(
            w, engine.space, engine.study, HumanConfig(phrasing_split="train"), np.random.default_rng(0)
        )
        answers[method] = [human.answer(kind.query(*robot.query(p, method, n).shown)) for n in range(1, 6)]
    runs = []
    for eng in (engine, _scrambled(engine)):
        assert eng is engine or not np.array_equal(eng.space.theta, engine.space.theta)
        history = {"language": [], "comparison": []}
        r = StudyRobot(eng, lambda pid, method, h=history: h[method])
        out = {"moves": [eng.improve(int(eng.study[0]), a.text) for a in answers["language"]]}
        for method in ("language", "comparison"):
            for n, answer in enumerate(answers[method], start=1):
                asked = (answer.query.shown,) if method == "language" else (answer.query.a, answer.query.b)
                assert r.query(p, method, n).shown == asked
                r.learn(p, method, n, answer)
                history[method].append(answer)
            out[method] = (
                [x.detach().numpy().copy() for x in r._learners[(p.id, method)][0].params],
                r.best(p, method),
            )
        runs.append(out)
    assert runs[0]["moves"] == runs[1]["moves"]
    for method in ("language", "comparison"):
        (pa, ba), (pb, bb) = runs[0][method], runs[1][method]
        assert ba == bb
        for x, y in zip(pa, pb):
            np.testing.assert_array_equal(x, y)
    assert isinstance(answers["language"][0].query, LanguageQuery)
