"""`langpref experiment seeds`: the seeds table and its mean and range computed from the models, resumed run by
run, a missing model trained with the default configuration, a finished run tied to its dataset."""

from __future__ import annotations

import json
import shutil

import pytest

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.experiments import seeds as experiment
from langpref.experiments.seeds import SeedsConfig, over_seeds, run_seeds_experiment


@pytest.fixture
def two_models(trained, tmp_path):
    """The shared tiny model as seed 0, and the same model as seed 1 (its evaluation is then the same)."""
    for seed in (0, 1):
        shutil.copytree(trained.out, tmp_path / "models" / f"m{seed}")
    return str(tmp_path / "models" / "m{seed}")


def test_the_table_and_its_summary_come_from_the_models(two_models, tiny_data, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        ["experiment", "seeds", "--env", "metaworld", "--data", str(tiny_data), "--seeds", "0,1",
         "--models", two_models, "--out", str(out), "--json"]
    )  # fmt: skip
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    accs = [summary["runs"][s]["accuracy"] for s in ("0", "1")]
    assert accs[0] == accs[1] and summary["over_seeds"]["mean"] == pytest.approx(accs[0])
    table = (out / "seeds.md").read_text()
    assert f"| metaworld | 1 | {accs[1]:.3f} |" in table and f"mean **{accs[0]:.3f}**" in table
    assert (out / "seeds.config.json").is_file()


def test_finished_seeds_are_not_evaluated_again_and_the_data_must_match(two_models, tiny_data, tmp_path, monkeypatch):
    cfg = SeedsConfig(env="metaworld", data=str(tiny_data), out=str(tmp_path / "o"), seeds=(0,), models=two_models)
    first = run_seeds_experiment(cfg)
    monkeypatch.setattr(experiment, "_evaluate", lambda *a: pytest.fail("seed 0 was evaluated twice"))
    assert run_seeds_experiment(cfg)["runs"] == first["runs"]
    other = tmp_path / "other-data"
    shutil.copytree(tiny_data, other)
    meta = json.loads((other / "meta.json").read_text())
    meta["config"]["seed"] = 12345  # another dataset: its checksum differs
    (other / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(LangprefError, match="another configuration"):
        run_seeds_experiment(SeedsConfig(**{**cfg.__dict__, "data": str(other)}))


def test_a_missing_model_is_trained_with_the_seed(two_models, tiny_data, tmp_path, monkeypatch):
    import langpref.model.train as train_module

    calls = []

    def fake_train(cfg, **kw):
        calls.append((cfg.seed, cfg.out))
        shutil.copytree(two_models.format(seed=0), cfg.out, dirs_exist_ok=True)

    monkeypatch.setattr(train_module, "train", fake_train)
    pattern = str(tmp_path / "new" / "seed{seed}")
    run_seeds_experiment(
        SeedsConfig(env="metaworld", data=str(tiny_data), out=str(tmp_path / "o"), seeds=(7,), models=pattern)
    )
    assert calls == [(7, pattern.format(seed=7))]


def test_bad_configs_are_refused_in_one_line():
    with pytest.raises(LangprefError, match="repeats"):
        SeedsConfig(env="metaworld", seeds=(1, 1)).resolved()
    with pytest.raises(LangprefError, match="seed"):
        SeedsConfig(env="metaworld", models="models/x").resolved()
    assert over_seeds([0.8, 0.9]) == pytest.approx({"mean": 0.85, "min": 0.8, "max": 0.9, "sd": 0.0707106781})
