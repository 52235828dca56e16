import json

import numpy as np

import pytest

from milliego_models.data import ChainSampler, expand_doppler, expand_panorama, load_dataset
from milliego_models.geometry import compose, euler_to_rot, pose_to_matrix, rot_to_euler
from milliego_models.h5 import load_h5
from milliego_models.synthetic import write_authors_h5


def test_expand_panorama_blocks_and_norm():
    rng = np.random.default_rng(0)
    pano = rng.random((16, 64)).astype(np.float32)
    norm = {"min": 0.0, "max": 2.0, "mean": 0.1}
    img = expand_panorama(pano, norm)
    assert img.shape == (64, 256) and img.dtype == np.float32
    for r, c in [(0, 0), (5, 17), (15, 63)]:
        block = img[4 * r:4 * r + 4, 4 * c:4 * c + 4]
        np.testing.assert_array_equal(block, np.float32(pano[r, c] / 2.0 - 0.1))
    assert expand_panorama(np.stack([pano, pano]), norm).shape == (2, 64, 256)


def test_expand_doppler_blocks_scale_and_clamp():
    dop = np.zeros((16, 64), np.float32)
    dop[0, 0], dop[5, 17], dop[15, 63], dop[3, 3] = -2.5, 1.0, 7.0, -30.0
    img = expand_doppler(dop)
    assert img.shape == (64, 256) and img.dtype == np.float32
    for (r, c), want in [((0, 0), -0.5), ((5, 17), 0.2), ((15, 63), 1.0), ((3, 3), -1.0), ((1, 1), 0.0)]:
        np.testing.assert_array_equal(img[4 * r:4 * r + 4, 4 * c:4 * c + 4], np.float32(want))


def test_doppler_input_puts_each_frames_doppler_between_its_depth_copies(datasets):
    d = load_dataset(datasets[0])
    assert d.doppler is not None and d.doppler.shape == d.frames.shape
    # Approaching points (ahead of a sensor moving forward) have negative radial velocity somewhere.
    assert (d.doppler < 0).any() and (d.doppler > 0).any()
    depth = d.radar([4, 9])
    d.radar_input = "depth_doppler"
    both = d.radar([4, 9])
    assert both.shape == depth.shape == (2, 6, 64, 256)
    for ch in (0, 2, 3, 5):  # depth where the paper's input has it
        np.testing.assert_array_equal(both[:, ch], depth[:, ch])
    p = d.pair[[4, 9]]
    np.testing.assert_array_equal(both[:, 1], expand_doppler(d.doppler[p[:, 0]]))
    np.testing.assert_array_equal(both[:, 4], expand_doppler(d.doppler[p[:, 1]]))
    assert not np.array_equal(both[:, 1], depth[:, 1])
    # A dataset without Doppler says so rather than feeding zeros.
    d.doppler = None
    with pytest.raises(ValueError, match="doppler"):
        d.radar([0])


def test_euler_roundtrip():
    rpy = np.array([[10.0, -20.0, 170.0], [0.5, 1.0, -45.0]])
    np.testing.assert_allclose(rot_to_euler(euler_to_rot(rpy)), rpy, atol=1e-9)
    rz = euler_to_rot(np.array([0, 0, 90.0]))
    np.testing.assert_allclose(rz @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_synthetic_dataset_follows_spec(datasets):
    train, _ = datasets
    manifest = json.loads((train / "manifest.json").read_text())
    assert manifest["format"] == "milliego-dataset" and manifest["version"] == 1
    d = load_dataset(train)
    assert len(d) == manifest["windows"] and len(d.frames) == manifest["frames"]
    assert d.radar([0, 1]).shape == (2, 6, 64, 256)
    gap = manifest["preprocess"]["gap"]
    for c in d.chains:
        assert np.all(d.pair[c, 1] - d.pair[c, 0] == gap)
        assert np.all(d.pair[c[1:], 0] == d.pair[c[:-1], 1])
        assert len(set(d.session_of[c])) == 1
        poses = compose(pose_to_matrix(d.gt_pose[d.pair[c[0], 0]]), d.label[c])
        np.testing.assert_allclose(poses[1:, :3, 3], d.gt_pose[d.pair[c, 1], :3], atol=1e-4)
    assert sum(len(c) for c in d.chains) == len(d)
    assert len(d.truncated(50)) == 50


def test_chain_sampler_sequences_and_ranks(datasets):
    d = load_dataset(datasets[0])
    s0 = ChainSampler(d.chains, 4, 3, rank=0, world=2, seed=1)
    s1 = ChainSampler(d.chains, 4, 3, rank=1, world=2, seed=1)
    b0, b1 = list(s0), list(s1)
    assert len(b0) == len(b1) > 0
    for seq in np.concatenate(b0):
        assert np.all(d.pair[seq[1:], 0] == d.pair[seq[:-1], 1])
    assert not set(np.concatenate(b0).ravel()) & set(np.concatenate(b1).ravel())


def test_h5_loader(tmp_path):
    path = write_authors_h5(tmp_path / "seq.h5", frames=30, seed=3)
    import h5py
    with h5py.File(path) as f:
        imu30, labels, imgs = f["imu_data"][:], f["label_data"][0], f["mmwave_middle_data"][:, 0, :, :, 0]
    d = load_h5(path)
    assert len(d) == 29 and len(d.chains) == 1 and len(d.chains[0]) == 29
    np.testing.assert_array_equal(d.label, labels)
    np.testing.assert_array_equal(d.imu[4], imu30[5, :20][::-1])  # newest-first -> oldest-first
    lo, hi = imgs.min(), imgs.max()
    assert d.norm["min"] == lo and d.norm["max"] == hi
    assert abs(d.norm["mean"] - ((imgs - lo) / (hi - lo)).mean()) < 1e-6
    radar = d.radar([3])[0]
    np.testing.assert_allclose(radar[0], (imgs[3] - lo) / (hi - lo) - d.norm["mean"], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(radar[5], (imgs[4] - lo) / (hi - lo) - d.norm["mean"], rtol=1e-5, atol=1e-6)
    pos = compose(np.eye(4), d.label)[:, :3, 3]
    np.testing.assert_allclose(d.gt_pose[:, :3], pos, atol=1e-6)
