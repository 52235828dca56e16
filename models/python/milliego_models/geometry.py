"""Pose conventions shared with the Rust side.

A relative pose label is tx, ty, tz [m], roll, pitch, yaw [deg] of the body at `cur` expressed in the
body frame at `prev`, with R = Rz(yaw) Ry(pitch) Rx(roll). Absolute poses are x y z qx qy qz qw.
"""
from __future__ import annotations

import numpy as np

LABEL_CONVENTION = ("pose = [tx, ty, tz] [m], [roll, pitch, yaw] [deg]: body at frame cur in the body frame at "
                    "frame prev; R = Rz(yaw) Ry(pitch) Rx(roll); T_cur = T_prev * T_rel")


def quat_to_rot(q: np.ndarray) -> np.ndarray:
    """[..., 4] (x, y, z, w) -> [..., 3, 3]."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def rot_to_quat(r: np.ndarray) -> np.ndarray:
    """[3, 3] -> (x, y, z, w) with w >= 0."""
    w = np.sqrt(max(0.0, 1 + r[0, 0] + r[1, 1] + r[2, 2])) / 2
    x = np.sqrt(max(0.0, 1 + r[0, 0] - r[1, 1] - r[2, 2])) / 2
    y = np.sqrt(max(0.0, 1 - r[0, 0] + r[1, 1] - r[2, 2])) / 2
    z = np.sqrt(max(0.0, 1 - r[0, 0] - r[1, 1] + r[2, 2])) / 2
    x = np.copysign(x, r[2, 1] - r[1, 2])
    y = np.copysign(y, r[0, 2] - r[2, 0])
    z = np.copysign(z, r[1, 0] - r[0, 1])
    q = np.array([x, y, z, w])
    return q / np.linalg.norm(q)


def euler_to_rot(rpy_deg: np.ndarray) -> np.ndarray:
    """[..., 3] roll, pitch, yaw [deg] -> Rz(yaw) Ry(pitch) Rx(roll) [..., 3, 3]."""
    r, p, y = np.moveaxis(np.deg2rad(rpy_deg), -1, 0)
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        np.stack([-sp, cp * sr, cp * cr], -1),
    ], -2)


def rot_to_euler(rot: np.ndarray) -> np.ndarray:
    """[..., 3, 3] -> roll, pitch, yaw [deg] for R = Rz(yaw) Ry(pitch) Rx(roll)."""
    roll = np.arctan2(rot[..., 2, 1], rot[..., 2, 2])
    pitch = np.arcsin(np.clip(-rot[..., 2, 0], -1, 1))
    yaw = np.arctan2(rot[..., 1, 0], rot[..., 0, 0])
    return np.rad2deg(np.stack([roll, pitch, yaw], -1))


def pose_to_matrix(pose: np.ndarray) -> np.ndarray:
    """[..., 7] x y z qx qy qz qw -> [..., 4, 4]."""
    t = np.zeros(pose.shape[:-1] + (4, 4))
    t[..., :3, :3] = quat_to_rot(pose[..., 3:7])
    t[..., :3, 3] = pose[..., :3]
    t[..., 3, 3] = 1
    return t


def relative_label(pose_prev: np.ndarray, pose_cur: np.ndarray) -> np.ndarray:
    """Label [6] from two absolute poses [7]."""
    rel = np.linalg.inv(pose_to_matrix(pose_prev)) @ pose_to_matrix(pose_cur)
    return np.concatenate([rel[:3, 3], rot_to_euler(rel[:3, :3])])


def label_to_matrix(label: np.ndarray) -> np.ndarray:
    t = np.zeros(label.shape[:-1] + (4, 4))
    t[..., :3, :3] = euler_to_rot(label[..., 3:6])
    t[..., :3, 3] = label[..., :3]
    t[..., 3, 3] = 1
    return t


def compose(start: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Chain relative labels [N,6] from a 4x4 start pose: returns the N+1 poses [N+1,4,4]."""
    out = [start]
    for rel in label_to_matrix(np.asarray(labels, dtype=np.float64)):
        out.append(out[-1] @ rel)
    return np.stack(out)


def umeyama_se3(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation R and translation t minimising |R src + t - dst|^2 (no scale). src, dst: [N,3]."""
    mu_s, mu_d = src.mean(0), dst.mean(0)
    cov = (dst - mu_d).T @ (src - mu_s) / len(src)
    u, _, vt = np.linalg.svd(cov)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1
    r = u @ s @ vt
    return r, mu_d - r @ mu_s


def aligned_errors(est: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Per-point position error [m] after SE(3) Umeyama alignment of est [N,3] onto gt [N,3]."""
    r, t = umeyama_se3(est, gt)
    return np.linalg.norm(est @ r.T + t - gt, axis=1)
