//! The shipped model (models/compact) in tract against the golden bundle written by
//! `python -m milliego_models.golden` with onnxruntime: the preprocessing expansion is bit-exact
//! with the trainer's, fp32 outputs agree to 1e-4 and int8 outputs stay within the int8 tolerance.
//! `MILLIEGO_MODEL_DIR` points the test at another model directory.

use milliego_models::{floats, read_meta, Model};
use milliego_preprocess::panorama::radar_tensor;
use milliego_preprocess::RadarInput;
use milliego_preprocess::{IMU_LEN, PANO_LEN, RADAR_LEN};
use safetensors::SafeTensors;
use std::path::PathBuf;
use tract_onnx::prelude::Tensor;

fn model_dir() -> PathBuf {
    std::env::var_os("MILLIEGO_MODEL_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("compact"))
}

fn f32s(st: &SafeTensors<'_>, name: &str) -> Vec<f32> {
    let t = st
        .tensor(name)
        .unwrap_or_else(|e| panic!("golden bundle lacks {name}: {e}"));
    assert_eq!(t.dtype(), safetensors::Dtype::F32, "{name}");
    t.data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

fn windows(st: &SafeTensors<'_>) -> usize {
    (0..)
        .take_while(|k| st.tensor(&format!("radar_{k}")).is_ok())
        .count()
}

fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn imu_rows(v: &[f32]) -> [[f32; 6]; IMU_LEN] {
    let mut out = [[0.0; 6]; IMU_LEN];
    for (row, src) in out.iter_mut().zip(v.chunks_exact(6)) {
        row.copy_from_slice(src);
    }
    out
}

#[test]
fn preprocessing_expansion_is_bit_exact_with_the_trainer() {
    let dir = model_dir();
    let bytes = std::fs::read(dir.join("golden.safetensors")).expect("golden bundle");
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let meta = read_meta(&dir.join("model.onnx")).unwrap();
    let n = windows(&st);
    assert!(n >= 2, "golden bundle has {n} windows");
    for k in 0..n {
        let prev: [f32; PANO_LEN] = f32s(&st, &format!("panorama_prev_{k}")).try_into().unwrap();
        let cur: [f32; PANO_LEN] = f32s(&st, &format!("panorama_cur_{k}")).try_into().unwrap();
        // A Doppler model's bundle carries the Doppler panoramas too (golden.py).
        let doppler = |name: String| -> [f32; PANO_LEN] {
            match meta.radar_input {
                RadarInput::Depth => [0.0; PANO_LEN],
                RadarInput::DepthDoppler => f32s(&st, &name).try_into().unwrap(),
            }
        };
        let (prev_d, cur_d) = (
            doppler(format!("doppler_prev_{k}")),
            doppler(format!("doppler_cur_{k}")),
        );
        let mut ours = Box::new([0.0f32; RADAR_LEN]);
        radar_tensor(
            meta.radar_input,
            (&prev, &prev_d),
            (&cur, &cur_d),
            &meta.norm,
            &mut ours,
        );
        let theirs = f32s(&st, &format!("radar_{k}"));
        let differing = ours
            .iter()
            .zip(&theirs)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(
            differing, 0,
            "window {k}: {differing} of {RADAR_LEN} values differ"
        );
        assert!(
            prev.iter().any(|v| *v > 0.0),
            "window {k} has an empty panorama"
        );
    }
}

#[test]
fn tract_matches_onnxruntime_on_the_golden_windows() {
    let dir = model_dir();
    let bytes = std::fs::read(dir.join("golden.safetensors")).expect("golden bundle");
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let n = windows(&st);
    for (file, key, tol) in [
        ("model.onnx", "fp32", 1e-4f32),
        // tract and onnxruntime round int8 intermediates differently in places.
        ("model-int8.onnx", "int8", milliego_models::INT8_TOLERANCE),
    ] {
        let mut m = Model::load(
            &dir.join(file),
            Some(&milliego_preprocess::Config::default()),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.meta().precision, key);
        assert!(m.meta().trained, "the shipped model is trained");
        let h = m.meta().hidden;
        let mut worst = 0.0f32;
        for k in 0..n {
            let radar = f32s(&st, &format!("radar_{k}"));
            let imu = imu_rows(&f32s(&st, &format!("imu_{k}")));
            let state = f32s(&st, &format!("state_{k}"));
            let radar_t = m.tensor(&[1, 6, 64, 256], &radar).unwrap();
            let imu_t = m.tensor(&[1, IMU_LEN, 6], imu.as_flattened()).unwrap();
            let state_t = Tensor::from_shape(&[1, 4, h], &state).unwrap();
            let (pose, state_out, std) = m.run_raw_with_std(radar_t, imu_t, state_t).unwrap();
            // The uncertainty head: in the bundle exactly when the model has it, and equal.
            let std_key = format!("pose_std_{key}_{k}");
            let has_std = st.names().iter().any(|n| **n == std_key);
            assert_eq!(std.is_some(), has_std, "{file}: pose_std output vs bundle");
            if let Some(std) = std {
                let want = f32s(&st, &std_key);
                let d = max_abs(&std, &want);
                assert!(
                    d <= tol * 5.0,
                    "{file} window {k}: pose_std {std:?} vs onnxruntime {want:?}"
                );
            }
            let want = f32s(&st, &format!("pose_{key}_{k}"));
            let d = max_abs(&pose, &want);
            worst = worst.max(d);
            assert!(
                d <= tol,
                "{file} window {k}: pose {pose:?} vs onnxruntime {want:?} (diff {d})"
            );
            let want_state = f32s(&st, &format!("state_out_{key}_{k}"));
            let ds = max_abs(&floats(&state_out).unwrap(), &want_state);
            assert!(ds <= tol * 5.0, "{file} window {k}: state differs by {ds}");
            // And against fp32: the int8 model must stay close to the model it came from.
            let fp = f32s(&st, &format!("pose_fp32_{k}"));
            assert!(
                max_abs(&pose, &fp) <= milliego_models::INT8_VS_FP32_TOLERANCE,
                "{file} window {k}: {pose:?} vs fp32 {fp:?}"
            );
        }
        eprintln!("{file}: worst pose difference to onnxruntime {worst:.2e} over {n} windows");
    }
}

#[test]
fn stepping_carries_state_only_for_stateful_models() {
    let dir = model_dir();
    let bytes = std::fs::read(dir.join("golden.safetensors")).expect("golden bundle");
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let mut m = Model::load(&dir.join("model.onnx"), None).unwrap();
    let radar = f32s(&st, "radar_1");
    let imu = imu_rows(&f32s(&st, "imu_1"));
    let first = m.step_tensors(&radar, &imu).unwrap();
    let second = m.step_tensors(&radar, &imu).unwrap();
    if m.meta().stateful {
        assert_ne!(
            first, second,
            "a stateful model's second step sees a new state"
        );
        m.reset();
        assert_eq!(
            m.step_tensors(&radar, &imu).unwrap(),
            first,
            "reset restores the zero state"
        );
    } else {
        assert_eq!(
            first, second,
            "a stateless model gives the same output for the same input"
        );
    }
    assert_eq!(m.steps(), if m.meta().stateful { 3 } else { 2 });
}

#[test]
fn bad_model_files_stop_with_a_clear_message() {
    let dir = tempfile_dir();
    let junk = dir.join("junk.onnx");
    std::fs::write(&junk, b"not an onnx file").unwrap();
    let e = Model::load(&junk, None).unwrap_err().to_string();
    assert!(e.contains("junk.onnx") && e.contains("cannot load"), "{e}");
    let missing = dir.join("missing.onnx");
    let e = Model::load(&missing, None).unwrap_err().to_string();
    assert!(e.contains("missing.onnx"), "{e}");
    // A model trained with other preprocessing settings is refused at load.
    let other = milliego_preprocess::Config {
        gap: 3,
        ..milliego_preprocess::Config::default()
    };
    let e = Model::load(&model_dir().join("model.onnx"), Some(&other))
        .unwrap_err()
        .to_string();
    assert!(e.contains("interface mismatch") && e.contains("gap"), "{e}");
}

fn tempfile_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("milliego-models-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn two_threads_give_the_same_outputs_as_one() {
    let dir = model_dir();
    let bytes = std::fs::read(dir.join("golden.safetensors")).expect("golden bundle");
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let n = windows(&st);
    for file in ["model.onnx", "model-int8.onnx"] {
        let path = dir.join(file);
        let mut one = Model::load_with_threads(&path, None, 1).unwrap();
        let mut two = Model::load_with_threads(&path, None, 2).unwrap();
        for k in 0..n {
            let radar = f32s(&st, &format!("radar_{k}"));
            let imu = imu_rows(&f32s(&st, &format!("imu_{k}")));
            let a = one.step_tensors(&radar, &imu).unwrap();
            let b = two.step_tensors(&radar, &imu).unwrap();
            // Whole tiles per thread: the same sums in the same order, bit for bit.
            assert_eq!(
                a.map(f32::to_bits),
                b.map(f32::to_bits),
                "{file} window {k}: {a:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn radar_zeroed_feeds_zeros_instead_of_the_images() {
    let dir = model_dir();
    let bytes = std::fs::read(dir.join("golden.safetensors")).expect("golden bundle");
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let prev: [f32; PANO_LEN] = f32s(&st, "panorama_prev_0").try_into().unwrap();
    let cur: [f32; PANO_LEN] = f32s(&st, "panorama_cur_0").try_into().unwrap();
    let imu = imu_rows(&f32s(&st, "imu_0"));
    let w = milliego_preprocess::window::Window {
        prev_seq: 0,
        cur_seq: 5,
        prev_frame: 0,
        cur_frame: 5,
        t_prev: 0.0,
        t_cur: 0.25,
        prev: &prev,
        cur: &cur,
        prev_doppler: &[0.0; PANO_LEN],
        cur_doppler: &[0.0; PANO_LEN],
        imu: &imu,
    };
    let mut m = Model::load(&dir.join("model.onnx"), None).unwrap();
    let with_radar = m.step(&w).unwrap();
    m.reset();
    m.set_radar_zeroed(true);
    let zeroed = m.step(&w).unwrap();
    m.reset();
    let by_hand = m.step_tensors(&vec![0.0; RADAR_LEN], &imu).unwrap();
    assert_eq!(
        zeroed, by_hand,
        "the ablation is the network on a zero radar tensor"
    );
    assert_ne!(zeroed, with_radar, "the radar input matters to the network");
    m.reset();
    m.set_radar_zeroed(false);
    assert_eq!(m.step(&w).unwrap(), with_radar);
}

#[test]
fn a_model_with_the_uncertainty_head_reports_its_deviation() {
    // An untrained tiny network with the head (`python -m milliego_models.fixtures`), and
    // onnxruntime's outputs for one input (radar zeros).
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures");
    let mut m = Model::load(
        &dir.join("tiny-uncertainty.onnx"),
        Some(&milliego_preprocess::Config::default()),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    assert!(m.has_uncertainty());
    assert_eq!(m.pose_std(), None, "no deviation before a step");
    let bytes = std::fs::read(dir.join("tiny-uncertainty.safetensors")).unwrap();
    let st = SafeTensors::deserialize(&bytes).unwrap();
    let imu = imu_rows(&f32s(&st, "imu"));
    let pose = m.step_tensors(&vec![0.0; RADAR_LEN], &imu).unwrap();
    let d = max_abs(&pose, &f32s(&st, "pose"));
    assert!(d <= 1e-4, "pose {pose:?} differs from onnxruntime by {d}");
    let std = m.pose_std().expect("a deviation after the step");
    let want = f32s(&st, "pose_std");
    assert!(
        max_abs(&std, &want) <= 1e-4,
        "{std:?} vs onnxruntime {want:?}"
    );
    assert!(std.iter().all(|s| *s > 0.0));
    m.reset();
    assert_eq!(m.pose_std(), None, "reset forgets the deviation");
    // The shipped model has no head: no deviation, ever.
    let mut plain = Model::load(&model_dir().join("model.onnx"), None).unwrap();
    assert!(!plain.has_uncertainty());
    plain.step_tensors(&vec![0.0; RADAR_LEN], &imu).unwrap();
    assert_eq!(plain.pose_std(), None);
}
