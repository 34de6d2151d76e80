"""A study's reward learner rebuilt from the database (as after a server restart, or once the cache dropped it)
equals the one the running server kept in memory: same reward on every trajectory, same best trajectory.

The running server refits after every answer, warm-started from the last fit; the rebuilt learner replays every
stored answer (same pairs, same negatives from the same seeds) and fits once. The linear reward's loss is strictly
convex (its L2 prior), so both reach the same minimum; they agree to the optimiser's tolerance, not bit for bit.
"""

import numpy as np
import torch

from langpref.study.session.engine import StudyRobot

FEEDBACK = ["Move faster.", "Go up more.", "Stay away from the button.", "Slow down.", "Get closer to the button."]


def test_a_learner_rebuilt_from_the_database_equals_the_one_in_memory(client, h, study_state):
    pid, headers = h.join(client)
    step, n = client.get(f"/api/participants/{pid}/step", headers=headers).json(), 0
    while step["kind"] != "done":
        r = client.post(
            f"/api/participants/{pid}/answer", json=h.answer_for(step, FEEDBACK[n % len(FEEDBACK)]), headers=headers
        )
        assert r.status_code == 200, r.text
        step, n = r.json(), n + 1
    conn = study_state.connect()
    p = study_state.participant(conn.execute("SELECT * FROM participants WHERE id=?", (pid,)).fetchone())
    live = study_state.robot
    restarted = StudyRobot(study_state.engine, study_state._history)  # a new server process on the same database
    phi = study_state.engine.space.phi
    for method in ("language", "comparison"):
        kept, answered = live._learners[(pid, method)][:2]
        assert answered == len(study_state._history(pid, method)) > 1
        rebuilt = restarted._learner(p, method, answered)
        assert rebuilt is not kept and rebuilt.num_queries == kept.num_queries == answered
        for a, b in zip(kept.batches, rebuilt.batches):  # the same pairs, negatives included
            np.testing.assert_array_equal(a.winners, b.winners)
            np.testing.assert_array_equal(a.losers, b.losers)
            np.testing.assert_array_equal(a.weights, b.weights)
        assert any(float(x.detach().abs().max()) > 1e-3 for x in kept.params)  # it learned something
        for x, y in zip(kept.params, rebuilt.params):
            torch.testing.assert_close(x, y, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(kept.predict(phi), rebuilt.predict(phi), rtol=1e-5, atol=1e-6)
        assert restarted.best(p, method) == live.best(p, method)
