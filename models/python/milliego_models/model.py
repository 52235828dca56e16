"""The milliEgo network (Lu et al., SenSys 2020), rebuilt from the authors' released Keras model.

I/O contract (one radar-frame pair per call, batch B):

    forward(radar [B,6,64,256] f32, imu [B,20,6] f32, state [B,4,H] f32)
        -> (pose [B,6] f32, state_out [B,4,H] f32)

- radar: `[expand(pano[prev])]*3 + [expand(pano[cur])]*3` on channels, normalised (see `data.expand_panorama`);
  with `radar_input="depth_doppler"` the middle channel of each frame is its Doppler image instead
  (`RADAR_INPUTS`, `data.stack_pair`).
- imu: accelerometer xyz [m/s^2] then gyro xyz [rad/s], body frame, oldest first, raw units.
- state: h1, c1, h2, c2 of the two fusion-LSTM layers (H = fusion hidden size). Stateless use feeds zeros.
- pose: tx, ty, tz [m], roll, pitch, yaw [deg] of the body at `cur` in the body frame at `prev`,
  R = Rz(yaw) Ry(pitch) Rx(roll).

Export constraints (tract runs the int8 graph): every LSTM is written as plain ops (MatMul, Add,
Sigmoid, Tanh, Mul) and every dense layer as `x @ W (+ b)` so ONNX gets MatMul (quantized to
QLinearMatMul), never Gemm or LSTM. Stride-2 'same' padding is explicit (`F.pad`, bottom/right heavier,
as TensorFlow does); `export.py` folds those Pad nodes into the Conv `pads` attribute.

LSTM gate order (all LSTMs here): i, f, g, o in the 4H axis, i.e. PyTorch's order (not Keras' i,f,c,o
nor ONNX's i,o,f,c), with standard sigmoid gates (the Keras original uses hard-sigmoid; we train from
scratch, so there are no Keras weights to port). One bias per LSTM, on the input projection, as Keras.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

RADAR_SHAPE = (6, 64, 256)
# Channels of the radar input that carry the same image (`data.stack_pair`: the previous frame's
# image 3 times, then the current one's 3 times, the authors' way of feeding FlowNet's 6 channels).
# The export folds each group into one channel of the first convolution (`onnx_utils.fold_copied_inputs`).
RADAR_COPIES = ((0, 1, 2), (3, 4, 5))
# What the six channels carry (model metadata `radar_input`) -> the groups of channels that always hold
# the same image. "depth": the paper's input above. "depth_doppler" (our extension, "milliEgo+D"): per
# frame its depth image, its Doppler image (`data.expand_doppler`), its depth image again.
RADAR_INPUTS = {"depth": RADAR_COPIES, "depth_doppler": ((0, 2), (1,), (3, 5), (4,))}
IMU_SHAPE = (20, 6)
# (kernel, stride) of the nine FlowNetS-like convolutions.
CONV_GEOMETRY = ((7, 2), (5, 2), (5, 2), (3, 1), (3, 2), (3, 1), (3, 2), (3, 1), (3, 2))


@dataclass(frozen=True)
class Config:
    name: str
    conv_channels: tuple[int, ...]
    imu_hidden: int
    imu_att_hidden: int
    cross_hidden: int
    fusion_hidden: int
    head_hidden: tuple[int, int]
    dropout: float = 0.25

    @property
    def radar_att_hidden(self) -> int:
        """Keras original: Dense(C/256) for C = 1024 -> 4; never below 4."""
        return max(4, self.conv_channels[-1] // 256)

    def to_dict(self) -> dict:
        return asdict(self)


CONFIGS = {
    # Exact reference sizes: 33,978,694 parameters.
    "paper": Config("paper", (64, 128, 256, 256, 512, 512, 512, 512, 1024), 128, 128, 128, 512, (128, 64)),
    # For training on a small CPU (see README for the measured speed).
    "compact": Config("compact", (8, 16, 32, 32, 64, 64, 96, 96, 128), 64, 64, 64, 128, (64, 32)),
    # Unit tests only.
    "tiny": Config("tiny", (4, 4, 8, 8, 8, 8, 8, 8, 16), 8, 8, 8, 16, (8, 8)),
}


def same_pads(size: int, kernel: int, stride: int) -> tuple[int, int]:
    """TensorFlow 'same' padding (before, after): the extra pixel goes after (bottom/right)."""
    out = -(-size // stride)
    total = max((out - 1) * stride + kernel - size, 0)
    return total // 2, total - total // 2


class Dense(nn.Module):
    """`x @ W + b` with W stored [in, out], so ONNX export emits MatMul (+ Add), never Gemm."""

    def __init__(self, n_in: int, n_out: int, bias: bool = True):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(n_in, n_out))
        self.bias = nn.Parameter(torch.zeros(n_out)) if bias else None
        nn.init.xavier_uniform_(self.weight)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = x @ self.weight
        return y + self.bias if self.bias is not None else y


class LSTMCell(nn.Module):
    """One LSTM step as plain ops. Gate order i, f, g, o; one bias (input projection)."""

    def __init__(self, n_in: int, hidden: int):
        super().__init__()
        self.hidden = hidden
        self.input = Dense(n_in, 4 * hidden, bias=True)
        self.recurrent = nn.Parameter(torch.empty(hidden, 4 * hidden))
        for k in range(4):
            nn.init.orthogonal_(self.recurrent.data[:, k * hidden:(k + 1) * hidden])
        with torch.no_grad():
            self.input.bias[hidden:2 * hidden].fill_(1.0)  # forget-gate bias 1, as Keras unit_forget_bias

    def step(self, x_proj: torch.Tensor, h: torch.Tensor, c: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One step given the already projected input `x @ W_x + b`."""
        z = x_proj + h @ self.recurrent
        n = self.hidden
        i, f, g, o = z[:, :n], z[:, n:2 * n], z[:, 2 * n:3 * n], z[:, 3 * n:]
        c = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
        h = torch.sigmoid(o) * torch.tanh(c)
        return h, c

    def forward(self, x, h, c):
        return self.step(self.input(x), h, c)


# Bounds of the predicted log-variance (uncertainty head): deviations from 3e-4 to 55 (m or deg).
LOG_VAR_RANGE = (-16.0, 8.0)


class MilliEgo(nn.Module):
    def __init__(self, config: Config | str = "paper", uncertainty: bool = False, radar_input: str = "depth"):
        super().__init__()
        cfg = CONFIGS[config] if isinstance(config, str) else config
        if radar_input not in RADAR_INPUTS:
            raise ValueError(f"radar input {radar_input!r}: one of {sorted(RADAR_INPUTS)}")
        self.config = cfg
        self.radar_input = radar_input
        self.uncertainty = bool(uncertainty)
        convs, pads = [], []
        c_in, (h, w) = RADAR_SHAPE[0], RADAR_SHAPE[1:]
        for c_out, (k, s) in zip(cfg.conv_channels, CONV_GEOMETRY):
            ph, pw = same_pads(h, k, s), same_pads(w, k, s)
            pads.append((pw[0], pw[1], ph[0], ph[1]))  # F.pad order: left, right, top, bottom
            convs.append(nn.Conv2d(c_in, c_out, k, s, padding=0))
            c_in, h, w = c_out, -(-h // s), -(-w // s)
        self.convs = nn.ModuleList(convs)
        self.pads = pads
        self.radar_features = c_in * h * w
        c_last = c_in
        for conv in self.convs:
            nn.init.kaiming_uniform_(conv.weight, a=0.1, nonlinearity="leaky_relu")
            nn.init.zeros_(conv.bias)

        self.radar_att1 = Dense(c_last, cfg.radar_att_hidden, bias=False)
        self.radar_att2 = Dense(cfg.radar_att_hidden, c_last, bias=False)

        self.imu_lstm = LSTMCell(IMU_SHAPE[1], cfg.imu_hidden)
        self.imu_features = IMU_SHAPE[0] * cfg.imu_hidden
        self.imu_att1 = Dense(self.imu_features, cfg.imu_att_hidden, bias=False)
        self.imu_att2 = Dense(cfg.imu_att_hidden, self.imu_features, bias=False)

        self.cross_radar1 = Dense(self.imu_features, cfg.cross_hidden, bias=False)
        self.cross_radar2 = Dense(cfg.cross_hidden, self.radar_features, bias=False)
        self.cross_imu1 = Dense(self.radar_features, cfg.cross_hidden, bias=False)
        self.cross_imu2 = Dense(cfg.cross_hidden, self.imu_features, bias=False)

        fused = self.radar_features + self.imu_features
        self.fusion1 = LSTMCell(fused, cfg.fusion_hidden)
        self.fusion2 = LSTMCell(cfg.fusion_hidden, cfg.fusion_hidden)
        h1, h2 = cfg.head_hidden
        self.trans = nn.ModuleList([Dense(cfg.fusion_hidden, h1), Dense(h1, h2), Dense(h2, 3)])
        self.rot = nn.ModuleList([Dense(cfg.fusion_hidden, h1), Dense(h1, h2), Dense(h2, 3)])
        if self.uncertainty:
            # Our extension (issue 19): log-variance of each pose component, read from the fusion
            # LSTM's output with the gradient stopped, so it never changes the pose path (a model
            # trained without it keeps its poses when the head is added and trained alone).
            self.std_head = nn.ModuleList([Dense(cfg.fusion_hidden, h1), Dense(h1, h2), Dense(h2, 6)])
            nn.init.zeros_(self.std_head[2].weight)
            nn.init.zeros_(self.std_head[2].bias)
        self.dropout = nn.Dropout(cfg.dropout)

    @property
    def hidden(self) -> int:
        return self.config.fusion_hidden

    def zero_state(self, batch: int, device=None) -> torch.Tensor:
        return torch.zeros(batch, 4, self.hidden, device=device)

    def radar_branch(self, radar: torch.Tensor) -> torch.Tensor:
        x = radar
        for conv, pad in zip(self.convs, self.pads):
            if any(pad):
                x = F.pad(x, pad)
            x = F.leaky_relu(conv(x), 0.1)
        mask = torch.sigmoid(self.radar_att2(F.relu(self.radar_att1(x.mean(dim=(2, 3))))))
        x = x * mask[:, :, None, None]
        return x.permute(0, 2, 3, 1).flatten(1)  # channels-last flatten, as Keras

    def imu_branch(self, imu: torch.Tensor) -> torch.Tensor:
        b = imu.shape[0]
        x_proj = self.imu_lstm.input(imu)  # [B,20,4H]: one MatMul for all steps
        h = imu.new_zeros(b, self.config.imu_hidden)
        c = imu.new_zeros(b, self.config.imu_hidden)
        outs = []
        for t in range(IMU_SHAPE[0]):
            h, c = self.imu_lstm.step(x_proj[:, t], h, c)
            outs.append(h)
        z = torch.stack(outs, dim=1).flatten(1)  # time-major, as Keras Flatten of [20,H]
        return z * torch.sigmoid(self.imu_att2(F.relu(self.imu_att1(z))))

    @staticmethod
    def _head(layers: nn.ModuleList, x: torch.Tensor, dropout: nn.Dropout) -> torch.Tensor:
        x = dropout(F.relu(layers[0](x)))
        x = F.relu(layers[1](x))
        return layers[2](x)

    def features(self, radar: torch.Tensor, imu: torch.Tensor) -> torch.Tensor:
        """Fused, attended features [B, radar_features + imu_features] (state independent)."""
        zr = self.radar_branch(radar)
        zi = self.imu_branch(imu)
        zr2 = zr * torch.sigmoid(self.cross_radar2(F.relu(self.cross_radar1(zi))))
        zi2 = zi * torch.sigmoid(self.cross_imu2(F.relu(self.cross_imu1(zr))))
        return self.dropout(torch.cat([zr2, zi2], dim=1))

    def recurrent(self, fused: torch.Tensor, state: torch.Tensor):
        """One fusion-LSTM step and the pose heads: (pose [B,6], state_out [B,4,H]); with the
        uncertainty head, pose is [B,12]: the 6 components, then their log-variances."""
        h1, c1 = self.fusion1(fused, state[:, 0], state[:, 1])
        h2, c2 = self.fusion2(h1, state[:, 2], state[:, 3])
        pose = torch.cat([self._head(self.trans, h2, self.dropout), self._head(self.rot, h2, self.dropout)], dim=1)
        if self.uncertainty:
            x = F.relu(self.std_head[1](F.relu(self.std_head[0](h2.detach()))))
            pose = torch.cat([pose, self.std_head[2](x).clamp(*LOG_VAR_RANGE)], dim=1)
        return pose, torch.stack([h1, c1, h2, c2], dim=1)

    def forward(self, radar: torch.Tensor, imu: torch.Tensor, state: torch.Tensor):
        return self.recurrent(self.features(radar, imu), state)


class Exported(nn.Module):
    """The exported interface: (pose [B,6], state_out [B,4,H]) plus, with the uncertainty head,
    pose_std [B,6], the predicted standard deviation of each component (m, deg)."""

    def __init__(self, net: MilliEgo):
        super().__init__()
        self.net = net

    def forward(self, radar, imu, state):
        pose, state_out = self.net(radar, imu, state)
        if not self.net.uncertainty:
            return pose, state_out
        return pose[:, :6], state_out, torch.exp(0.5 * pose[:, 6:])


class Unrolled(nn.Module):
    """Training wrapper: L consecutive windows per item, features batched, fusion LSTM stepped.

    forward(radar [B,L,6,64,256], imu [B,L,20,6], state [B,4,H]) -> (poses [B,L,6], state_out).
    One module call per sequence, so DDP sees exactly one forward per backward.
    """

    def __init__(self, net: MilliEgo):
        super().__init__()
        self.net = net

    def forward(self, radar, imu, state):
        b, L = radar.shape[:2]
        feats = self.net.features(radar.flatten(0, 1), imu.flatten(0, 1)).view(b, L, -1)
        poses = []
        for t in range(L):
            pose, state = self.net.recurrent(feats[:, t], state)
            poses.append(pose)
        return torch.stack(poses, 1), state


def count_params(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def build(config: str, seed: int | None = None, uncertainty: bool = False) -> MilliEgo:
    if seed is not None:
        torch.manual_seed(seed)
    return MilliEgo(config, uncertainty)


PAPER_PARAMS = 33_978_694  # Keras rebuild of build_model_cross_att; paper reports 33.9M
assert math.isclose(PAPER_PARAMS / 1e6, 33.98, abs_tol=0.01)
