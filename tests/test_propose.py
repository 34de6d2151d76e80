"""The trajectory proposer (langpref.propose): surrogate, search, real rollouts that replay, and what it can see."""

from __future__ import annotations

import copy
import dataclasses
import gc
import sys
import types
from contextlib import contextmanager

import numpy as np
import pytest

from langpref.feedback.humans import normalised_reward
from langpref.feedback.language import LanguageHuman
from langpref.feedback.space import perfect_latent_space
from langpref.improve import ImproveConfig, human_weights, run_improvement
from langpref.propose import AffineScale, GeneratedStore, Generation, ProposeConfig, Proposer, Surrogate, dataset_units

pytestmark = pytest.mark.slow  # runs the simulator (`pytest -m 'not slow'` leaves it out)

HORIZON = 30


@pytest.fixture(scope="module")
def generation(real_data):
    space = perfect_latent_space(real_data)
    return space, Generation.open(real_data, space, ProposeConfig(rollouts=2, search_generations=5, optimize_rounds=2))


def test_surrogate_fits_a_hand_built_map():
    rng = np.random.default_rng(0)
    f = lambda U: np.stack([np.sin(3 * U[:, 0]) + U[:, 1], U[:, 2] * U[:, 3], U[:, 0] ** 2 - U[:, 3]], 1)  # noqa
    U, V = rng.random((300, 4)), rng.random((50, 4))
    pred = Surrogate(1e-3).fit(U, f(U)).predict(V)
    r2 = 1 - ((pred - f(V)) ** 2).sum() / ((f(V) - f(V).mean(0)) ** 2).sum()
    assert r2 > 0.97
    assert Surrogate(1e-3).fit(U, U @ np.ones((4, 2))).predict(V) == pytest.approx(V @ np.ones((4, 2)), abs=1e-2)


def test_the_search_finds_a_toy_optimum_with_a_tiny_budget():
    rng = np.random.default_rng(1)
    M = rng.standard_normal((14, 5))
    U = rng.random((150, 14))
    target = np.full(14, 0.3)
    target[:3] = [0.8, 0.1, 0.6]
    proposer = Proposer(
        "metaworld",
        HORIZON,
        U,
        U @ M,
        embed=lambda t: None,
        cfg=ProposeConfig(rollouts=3, search_generations=60, search_sigma=0.3),
    )
    goal = target @ M
    X, scores = proposer.search(lambda P: -np.linalg.norm(P - goal, axis=1), np.full(14, 0.5), seed=3)
    assert len(X) == 3 and scores[0] == max(scores)
    assert np.linalg.norm((X[0] - target) @ M) < 0.05 * np.linalg.norm(goal)


def test_dataset_units_are_the_controllers_that_made_it(real_data):
    from langpref.tasks import get_simulator

    units = dataset_units(real_data)
    sim = get_simulator("metaworld")
    t = real_data.load(4)
    assert sim.make_controller(units[4], np.random.default_rng(t.seed)).params == pytest.approx(t.controller_params)


def test_a_generated_trajectory_replays_bit_identically(generation, tmp_path):
    from langpref.dataset.generate import rollout
    from langpref.dataset.storage import load_dataset
    from langpref.tasks import get_simulator, get_task

    space, gen = generation
    psi = space.psi_of(space.table("test").texts[0])
    proposal = gen.proposer(key=(5,)).propose(lambda P: P @ psi, gen.units[0], (0,))
    assert proposal.scores[0] == max(proposal.scores) and len(proposal.trajectories) == 2
    assert proposal.scores == pytest.approx(proposal.phi @ psi)
    store = GeneratedStore(tmp_path / "gen", "metaworld", HORIZON, {"why": "test"})
    store.add(proposal.trajectories[0], run=[0], iteration=1)
    stored = load_dataset(tmp_path / "gen").load(0)
    env = get_simulator("metaworld").make_env(HORIZON)
    again = rollout(env, get_task("metaworld"), np.array(stored.controller_params["unit"]), stored.seed, HORIZON, 0)
    for name in ("observations", "actions", "step_features", "qpos", "qvel"):
        assert np.array_equal(getattr(again, name), getattr(stored, name)), name


def _reachable(*roots):
    """Every object reachable from `roots` through instances, containers, closures and bound methods (not through
    modules, classes or a function's globals, which reach everything loaded)."""
    module_dicts = {id(m.__dict__) for m in list(sys.modules.values()) if m is not None}
    seen, stack, out = set(), list(roots), []
    while stack:
        obj = stack.pop()
        if id(obj) in seen or isinstance(obj, (types.ModuleType, type)) or id(obj) in module_dicts:
            continue
        seen.add(id(obj))
        out.append(obj)
        if isinstance(obj, types.FunctionType):
            stack.extend([obj.__closure__ or (), obj.__defaults__ or (), obj.__kwdefaults__ or {}])
            continue
        stack.extend(gc.get_referents(obj))
    return out


def _assert_unreachable(roots, space, gen, w) -> None:
    """None of the synthetic human, its weights, the humans' theta or the experimenter's feature scale is reachable
    from `roots`, as those objects or as copies of the weights and of theta. (The oracle's phi is (theta, 3): the
    proposer holds theta's numbers by design, one column wider, which is all this check can say of them; whether it
    *uses* the experimenter's copies, or a rollout's features, is `_blinded`'s check.)"""
    for obj in _reachable(*roots):
        assert not isinstance(obj, LanguageHuman), "a synthetic human is reachable"
        assert obj is not w and obj is not space.theta, "the human's weights or the humans' theta are reachable"
        assert obj is not gen.scale and obj is not gen, "the experimenter's feature scale is reachable"
        if isinstance(obj, np.ndarray) and obj.dtype.kind == "f":
            assert not (obj.shape == w.shape and np.allclose(obj, w)), "a copy of the human's weights is reachable"
            assert not (obj.shape == space.theta.shape and np.allclose(obj, space.theta)), "a copy of theta"


class _Poison:
    def __call__(self, *args, **kwargs):
        raise AssertionError("the optimiser scored a rollout's features on the experimenter's scale")


@contextmanager
def _blinded(space, gen, w, embedders: list):
    """While inside: the human's weights and the humans' theta are NaN (in place, so every holder of those arrays
    sees NaN), the experimenter's feature scale (`gen.scale`, what `gen.theta` scores a rollout with) raises, and
    every new rollout's step features, so its features, are NaN to all but the embedder. The oracle's embedder
    reads a rollout's features, as phi = (features, 3) is its definition: `embedders` (a list, filled inside) gives
    each embedder to wrap so that it alone sees them (a learned model's encoder reads observations only)."""
    from langpref.dataset import generate as generate_module

    assert not np.shares_memory(space.theta, space.phi)  # poisoning theta must leave phi as it is
    real_rollout, hidden = generate_module.rollout, {}
    saved_w, saved_theta, saved_scale = w.copy(), space.theta.copy(), gen.scale

    def rollout(*args, **kwargs):
        traj = real_rollout(*args, **kwargs)
        hidden[id(traj)] = traj.step_features
        traj.step_features = np.full_like(traj.step_features, np.nan)
        return traj

    def unveil(embed):
        return lambda traj: embed(dataclasses.replace(traj, step_features=hidden[id(traj)]))

    embedders.append(unveil)
    w[:], space.theta[:] = np.nan, np.nan
    gen.scale, generate_module.rollout = _Poison(), rollout
    try:
        yield
    finally:
        w[:], space.theta[:] = saved_w, saved_theta
        gen.scale, generate_module.rollout = saved_scale, real_rollout
    assert hidden, "no rollout ran while blinded"


def _assert_same_proposal(a, b) -> None:
    for name in ("units", "phi", "scores", "surrogate_scores"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("strategy", ["paper", "history"])
def test_the_proposer_cannot_reach_the_true_reward(generation, monkeypatch, strategy):
    """Every generation step of a real improvement run runs twice, the second time on a copy of the proposer with
    the human's weights, the humans' theta and the rollouts' features poisoned (`_blinded`): the same proposal. And
    none of them is reachable from the proposer or the objective it is given."""
    space, gen = generation
    w = human_weights(len(space.feature_names), 0, 0)
    seen = []
    real = Proposer.propose

    def twice(self, objective, start, step=()):
        _assert_unreachable((self, objective, start, step), space, gen, w)
        blind = copy.copy(self)
        blind.surrogate = copy.deepcopy(self.surrogate)
        embedders: list = []
        with _blinded(space, gen, w, embedders):
            blind.embed = embedders[0](self.embed)
            blinded = real(blind, objective, start, step)
        proposal = real(self, objective, start, step)
        _assert_same_proposal(proposal, blinded)
        seen.append(step)
        return proposal

    monkeypatch.setattr(Proposer, "propose", twice)
    cfg = ImproveConfig(iterations=2, seeds=1, candidate_split="generated", strategy=strategy)
    run = run_improvement(space, w, cfg, (0, 0), gen)
    assert seen == [(0,), (1,)]
    assert len(run.reward) == 3 and len(run.generated) == 3 and len(run.step_s) == 2


def test_optimize_never_reads_the_humans_weights_or_the_true_features(generation, monkeypatch):
    """`learn-reward --optimize`: r_xi's optimum, made again with the human's weights, the humans' theta and the
    rollouts' features poisoned (`_blinded`) once the queries are answered, is the same optimum; the experimenter
    then scores it with them."""
    from langpref.reward import LearnRewardConfig, loop, run_reward_learning

    space, gen = generation
    w = human_weights(len(space.feature_names), 0, 0)
    real, made = loop.optimize_reward, []

    def twice(generation, learner, run_seed=(0,)):
        assert generation is gen
        _assert_unreachable((learner,), space, gen, w)
        clean = real(generation, learner, run_seed)
        embedders: list = []
        real_embed = gen.embed
        with _blinded(space, gen, w, embedders):
            gen.embed = embedders[0](real_embed)
            try:
                blinded = real(generation, learner, run_seed)
            finally:
                gen.embed = real_embed
        _assert_same_proposal(clean, blinded)
        assert len(clean.trajectories) == gen.cfg.rollouts * gen.cfg.optimize_rounds
        made.append(clean)
        return clean

    monkeypatch.setattr(loop, "optimize_reward", twice)
    cfg = LearnRewardConfig(feedback="language", queries=4, humans=1, seeds=1)
    run = run_reward_learning(space, w, cfg, (0, 0, 0), generation=gen)
    assert len(made) == 1 and np.isfinite(run.optimized_true_reward)
    # the experimenter's score of the optimum, on the eval split's scale, with the weights and features restored
    R_eval = space.theta[space.split(cfg.eval_split)] @ w
    expected = normalised_reward(gen.theta(made[0].trajectories[0])[None] @ w, R_eval)[0]
    assert run.optimized_true_reward == pytest.approx(float(expected))


def test_generated_improvement_keeps_the_split_scale(generation, tmp_path):
    space, gen = generation
    w = human_weights(len(space.feature_names), 0, 1)
    base = run_improvement(space, w, ImproveConfig(iterations=3, seeds=1), (0, 1))
    store = GeneratedStore(tmp_path / "shown", "metaworld", HORIZON)
    run = run_improvement(
        space, w, ImproveConfig(iterations=3, seeds=1, candidate_split="generated"), (0, 1), gen, store
    )
    assert run.shown[0] == base.shown[0] and run.reward[0] == base.reward[0]  # same start, same normalisation
    assert run.optimal_raw == base.optimal_raw
    n = len(space.phi)
    assert [s >= n for s in run.shown] == run.generated
    assert len(store) == len({s for s in run.shown if s >= n}) and len(store) > 0, "no generated trajectory shown"
    # the stored trajectories are the ones scored: each one's true reward is one of the run's
    raw = np.array([gen.theta(stored) for stored in _stored(tmp_path / "shown")]) @ w
    assert len(raw) == len(store) and np.isin(np.round(raw, 9), np.round(run.raw_reward, 9)).all()


def _stored(root):
    from langpref.dataset.storage import load_dataset

    ds = load_dataset(root)
    return [ds.load(i) for i in range(len(ds))]


def test_learn_reward_optimize_scores_the_generated_optimum(generation):
    from langpref.reward import LearnRewardConfig, learn_reward

    space, gen = generation
    out = learn_reward(space, LearnRewardConfig(queries=4, humans=2, seeds=1), progress=False, generation=gen)
    made = np.array(out["optimized_true_reward"])
    assert len(made) == 2 and np.isfinite(made).all()
    assert out["optimized_true_reward_mean"] == pytest.approx(made.mean())
    assert out["optimized_beats_best_of_split"] == (made > 1.0).mean()  # the share of its own runs, not any number


def test_the_recorded_baseline_is_the_final_reward_s_pick_over_every_split(generation):
    from langpref.feedback.humans import normalised_reward, true_reward
    from langpref.reward import LearnRewardConfig, human_weights, run_reward_learning

    space, gen = generation
    cfg = LearnRewardConfig(queries=4, humans=1, seeds=1)
    w = human_weights(len(space.feature_names), cfg.seed, 0)
    learners = []
    curves = run_reward_learning(space, w, cfg, (cfg.seed, 0, 0), generation=gen, learners=learners)
    pick = int(np.argmax(learners[0].predict(space.phi)))
    R_test = true_reward(w, space.theta[space.split(cfg.eval_split)])
    assert curves.recorded_true_reward == pytest.approx(
        float(normalised_reward(true_reward(w, space.theta[[pick]]), R_test)[0])
    )
    assert pick not in set(space.split(cfg.eval_split).tolist()) or curves.recorded_true_reward == pytest.approx(
        curves.true_reward_of_best[-1]
    )  # a pick inside the test split is the test pick


def test_affine_scale_recovers_the_space_scale(real_data):
    from langpref.feedback.space import paper_theta

    feats = np.asarray(real_data.features)
    for theta in (perfect_latent_space(real_data).theta, paper_theta(real_data)):
        assert AffineScale.fit(feats, theta)(feats) == pytest.approx(theta)
