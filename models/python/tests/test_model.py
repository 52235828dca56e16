import pytest
import torch

from milliego_models.model import CONFIGS, PAPER_PARAMS, MilliEgo, Unrolled, count_params
from milliego_models.train import pose_loss


def test_paper_parameter_count():
    n = count_params(MilliEgo("paper"))
    assert abs(n - 33.9e6) / 33.9e6 < 0.01
    assert n == PAPER_PARAMS  # the Keras rebuild of the authors' model


@pytest.mark.parametrize("config", sorted(CONFIGS))
def test_shapes(config):
    net = MilliEgo(config).eval()
    with torch.no_grad():
        pose, state = net(torch.rand(2, 6, 64, 256), torch.randn(2, 20, 6), net.zero_state(2))
    assert pose.shape == (2, 6)
    assert state.shape == (2, 4, CONFIGS[config].fusion_hidden)
    assert net.radar_features == 4 * CONFIGS[config].conv_channels[-1]


def test_training_steps_decrease_loss():
    torch.manual_seed(0)
    net = MilliEgo("tiny")
    radar, imu = torch.rand(8, 1, 6, 64, 256), torch.randn(8, 1, 20, 6)
    label = torch.randn(8, 1, 6) * torch.tensor([0.3, 0.3, 0.05, 2, 2, 5])
    model = Unrolled(net)
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)

    def loss():
        return pose_loss(model(radar, imu, net.zero_state(8))[0], label, 0.01)[0]

    net.eval()
    with torch.no_grad():
        before = loss().item()
    for _ in range(30):
        net.train()
        opt.zero_grad()
        loss().backward()
        opt.step()
    net.eval()
    with torch.no_grad():
        after = loss().item()
    assert after < 0.8 * before, (before, after)


def test_state_is_used_and_updated():
    torch.manual_seed(0)
    net = MilliEgo("tiny").eval()
    radar, imu = torch.rand(1, 6, 64, 256), torch.randn(1, 20, 6)
    zero = net.zero_state(1)
    with torch.no_grad():
        pose0, state1 = net(radar, imu, zero)
        pose1, state2 = net(radar, imu, state1)
    assert not torch.allclose(state1, zero)
    assert not torch.allclose(state2, state1)
    assert not torch.allclose(pose0, pose1)  # the pose depends on the state input


def test_unrolled_matches_stepping():
    torch.manual_seed(0)
    net = MilliEgo("tiny").eval()
    radar, imu = torch.rand(2, 3, 6, 64, 256), torch.randn(2, 3, 20, 6)
    with torch.no_grad():
        poses, state_u = Unrolled(net)(radar, imu, net.zero_state(2))
        state = net.zero_state(2)
        for t in range(3):
            pose, state = net(radar[:, t], imu[:, t], state)
            torch.testing.assert_close(poses[:, t], pose)
    torch.testing.assert_close(state_u, state)
