import imageio.v2 as imageio
import pytest

from langpref.dataset.generate import GenerateConfig, generate
from langpref.dataset.render import render_trajectory
from langpref.errors import LangprefError

pytestmark = pytest.mark.slow  # runs the simulator (`pytest -m 'not slow'` leaves it out)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("render") / "mw"
    generate(GenerateConfig(env="metaworld", out=root, num_trajectories=3, horizon=12, workers=1, seed=1))
    return root


@pytest.mark.parametrize("suffix", [".mp4", ".webm"])
def test_render_writes_a_playable_video(dataset, tmp_path, suffix):
    out = render_trajectory(dataset, 0, tmp_path / f"v{suffix}", width=160, height=120)
    reader = imageio.get_reader(out)
    frames = [f for f in reader]
    assert len(frames) == 12 and frames[0].shape == (120, 160, 3)
    assert frames[0].std() > 10  # a real scene, not a blank image


def test_frames_are_upright(dataset):
    """The table is below the horizon: the bottom band is warmer (wood) than the top band (sky/wall)."""
    from langpref.dataset.storage import load_dataset
    from langpref.tasks import make_env
    from langpref.tasks.render import render_frames

    traj = load_dataset(dataset).load(0)
    env = make_env("metaworld", 12)
    env.reset(traj.seed)
    frame = render_frames(env, traj.qpos[:1], traj.qvel[:1], 160, 120)[0].astype(float)
    env.close()
    top, bottom = frame[:20], frame[-20:]
    warmth = lambda band: (band[..., 0] - band[..., 2]).mean()  # noqa: E731
    assert warmth(bottom) > warmth(top)


def test_bad_requests(dataset, tmp_path):
    with pytest.raises(LangprefError, match="out of range"):
        render_trajectory(dataset, 99, tmp_path / "x.mp4")
    with pytest.raises(LangprefError, match="unsupported video format"):
        render_trajectory(dataset, 0, tmp_path / "x.gif")
