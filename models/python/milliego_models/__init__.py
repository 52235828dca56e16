"""milliEgo learned radar-inertial odometry: PyTorch model, training, ONNX export and int8 quantization.

The Rust side (`milliego` CLI, tract runtime) consumes the ONNX files written here; the model I/O
contract is documented in `model.py` and in `models/python/README.md`.
"""
