import numpy as np

from langpref.model.encoders import normalisation_stats, step_input_dim, step_inputs


def test_step_inputs_carry_the_change_of_observation_since_the_previous_step():
    obs = np.array([[[0.0, 1.0], [0.5, 1.0], [2.0, 0.0]]])  # one trajectory, T = 3, obs_dim = 2
    act = np.array([[[9.0], [8.0], [7.0]]])
    x = step_inputs(obs, act, observation_deltas=True)
    assert x.shape == (1, 3, step_input_dim(2, 1, True)) == (1, 3, 5)
    np.testing.assert_allclose(x[0, :, 2:4], [[0.0, 0.0], [0.5, 0.0], [1.5, -1.0]])  # zero at t = 0
    np.testing.assert_allclose(x[0, :, 4], [9.0, 8.0, 7.0])
    assert step_inputs(obs, act, observation_deltas=False).shape == (1, 3, step_input_dim(2, 1, False)) == (1, 3, 3)


def test_a_constant_input_normalises_to_zero_not_infinity():
    steps = np.zeros((2, 4, 3), np.float32)
    steps[..., 0] = np.arange(8).reshape(2, 4)
    mean, std = normalisation_stats(steps)
    assert std[1] == 1.0 and std[2] == 1.0 and std[0] > 0
    assert np.all(np.isfinite((steps - mean) / std))


def test_padding_does_not_change_phi():
    """A trajectory padded to a longer horizon embeds as its own steps' mean (the paper's footnote 1)."""
    import torch

    from langpref.model.encoders import TrajectoryEncoder

    torch.manual_seed(0)
    enc = TrajectoryEncoder(in_dim=3, hidden=[8], latent_dim=4)
    short = torch.randn(1, 5, 3)
    padded = torch.cat([short, short[:, -1:].repeat(1, 7, 1)], dim=1)
    other = torch.randn(1, 12, 3)
    phi = enc(torch.cat([padded, other]), torch.tensor([5, 12]))
    torch.testing.assert_close(phi[0], enc(short)[0])
    torch.testing.assert_close(phi[1], enc(other)[0])
    assert not torch.allclose(enc(padded)[0], enc(short)[0])  # without lengths the padding would count


def test_normalisation_ignores_padding():
    steps = np.zeros((2, 4, 1), np.float32)
    steps[0, :, 0] = [1.0, 3.0, 3.0, 3.0]  # two real steps, padded with the last
    steps[1, :, 0] = [5.0, 7.0, 9.0, 11.0]
    mean, _ = normalisation_stats(steps, np.array([2, 4]))
    assert mean[0] == np.float32((1 + 3 + 5 + 7 + 9 + 11) / 6)
