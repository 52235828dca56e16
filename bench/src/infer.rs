//! Model inference, batch 1, one thread: tract (this crate, each graph in a child process so its
//! peak RSS delta is its own) against onnxruntime (the `milliego_models.ort_bench` Python module,
//! one thread, same inputs, same number of runs).

use crate::report::{percentile, Better, Row};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;
use tract_onnx::prelude::*;

/// Latency and memory of one graph on one engine.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    /// Median latency \[ms\].
    pub median_ms: f64,
    /// 99th percentile latency \[ms\] (nearest rank).
    pub p99_ms: f64,
    /// Timed runs.
    pub runs: usize,
    /// Peak RSS minus RSS before loading \[MB\] (load, optimisation and the runs).
    pub rss_delta_mb: f64,
    /// Load + optimise time \[s\].
    pub load_s: f64,
    /// The pose of the timed input (to compare engines).
    pub pose: Vec<f32>,
}

/// The three inputs of one window, flat.
#[derive(Debug, Clone)]
pub struct Inputs {
    /// 1 x 6 x 64 x 256.
    pub radar: Vec<f32>,
    /// 1 x 20 x 6.
    pub imu: Vec<f32>,
    /// 1 x 4 x hidden (as stored; replaced by zeros when the width differs).
    pub state: Vec<f32>,
}

fn f32s(t: &safetensors::tensor::TensorView<'_>) -> Vec<f32> {
    t.data()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// Window 0 of a golden bundle (`radar_0`, `imu_0`, `state_0`).
pub fn load_inputs(bundle: &Path) -> Result<Inputs, String> {
    let bytes = std::fs::read(bundle).map_err(|e| format!("{}: {e}", bundle.display()))?;
    let st = safetensors::SafeTensors::deserialize(&bytes)
        .map_err(|e| format!("{}: {e}", bundle.display()))?;
    let get = |n: &str| {
        st.tensor(n)
            .map(|t| f32s(&t))
            .map_err(|e| format!("{}: {n}: {e}", bundle.display()))
    };
    Ok(Inputs {
        radar: get("radar_0")?,
        imu: get("imu_0")?,
        state: get("state_0")?,
    })
}

fn status_kb(key: &str) -> Option<f64> {
    std::fs::read_to_string("/proc/self/status")
        .ok()?
        .lines()
        .find(|l| l.starts_with(key) && l[key.len()..].starts_with(':'))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()
}

/// Resets the peak RSS (VmHWM) to the current RSS (Linux `clear_refs` 5).
fn clear_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// The `hidden` field of the graph's `milliego` metadata (the state width). Read leniently: the
/// paper-size graphs carry no normalisation, so `milliego_models::read_meta` refuses them.
pub fn hidden_of(path: &Path) -> Result<usize, String> {
    let proto = tract_onnx::onnx()
        .proto_model_for_path(path)
        .map_err(|e| format!("{}: {e:#}", path.display()))?;
    proto
        .metadata_props
        .iter()
        .find(|p| p.key == "milliego")
        .and_then(|p| serde_json::from_str::<serde_json::Value>(&p.value).ok())
        .and_then(|v| v["hidden"].as_u64())
        .map(|h| h as usize)
        .ok_or_else(|| format!("{}: no milliego.hidden in the metadata", path.display()))
}

/// Loads `path` as `Model::load` does (input facts, `into_optimized`, one reused state), with
/// `threads` tract threads; returns the state and the hidden size.
pub fn load_state(path: &Path, threads: usize) -> Result<(TypedSimpleState, usize), String> {
    let e = |e: TractError| format!("{}: {e:#}", path.display());
    let h = hidden_of(path)?;
    let mut model = tract_onnx::onnx().model_for_path(path).map_err(e)?;
    for (i, s) in [vec![1, 6, 64, 256], vec![1, 20, 6], vec![1, 4, h]]
        .iter()
        .enumerate()
    {
        model
            .set_input_fact(i, f32::fact(s.as_slice()).into())
            .map_err(e)?;
    }
    let mut typed = model.into_optimized().map_err(e)?;
    milliego_accel::prepare(&mut typed).map_err(e)?;
    let plan = plan_with_threads(typed, threads)?;
    Ok((TypedSimpleState::new(&plan).map_err(e)?, h))
}

fn feed(inputs: &Inputs, h: usize) -> Result<TVec<TValue>, String> {
    let e = |e: TractError| format!("{e:#}");
    let zeros;
    let st: &[f32] = if inputs.state.len() == 4 * h {
        &inputs.state
    } else {
        zeros = vec![0.0; 4 * h];
        &zeros
    };
    Ok(tvec![
        Tensor::from_shape(&[1, 6, 64, 256], &inputs.radar)
            .map_err(e)?
            .into(),
        Tensor::from_shape(&[1, 20, 6], &inputs.imu)
            .map_err(e)?
            .into(),
        Tensor::from_shape(&[1, 4, h], st).map_err(e)?.into(),
    ])
}

/// Times `path` in tract in this process: `warmup` then `runs` calls of the optimised plan
/// (loaded as `milliego_models::Model::load` does), fresh input tensors each call. State input:
/// the bundle's when its width fits, else zeros.
pub fn tract_time(
    path: &Path,
    inputs: &Inputs,
    runs: usize,
    warmup: usize,
    threads: usize,
) -> Result<Timing, String> {
    clear_peak();
    let base = status_kb("VmRSS").unwrap_or(f64::NAN);
    let t0 = Instant::now();
    let (mut state, h) = load_state(path, threads)?;
    let load_s = t0.elapsed().as_secs_f64();
    let mut once = || -> Result<Vec<f32>, String> {
        let out = state.run(feed(inputs, h)?).map_err(|e| format!("{e:#}"))?;
        let pose = out.first().ok_or("no output")?;
        milliego_models::floats(pose)
    };
    let mut pose = Vec::new();
    for _ in 0..warmup {
        pose = once()?;
    }
    let mut ms = Vec::with_capacity(runs);
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        pose = once()?;
        ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let peak = status_kb("VmHWM").unwrap_or(f64::NAN);
    Ok(Timing {
        median_ms: percentile(&ms, 50.0).unwrap_or(f64::NAN),
        p99_ms: percentile(&ms, 99.0).unwrap_or(f64::NAN),
        runs: ms.len(),
        rss_delta_mb: (peak - base) / 1024.0,
        load_s,
        pose,
    })
}

/// Times `path` in tract in a child process (`milliego-bench --tract-one`), so its peak RSS
/// delta does not overlap with other graphs; `accel` false times tract's stock plan
/// (`MILLIEGO_ACCEL=0`: without `milliego-accel`'s passes).
pub fn tract_time_child(
    path: &Path,
    bundle: &Path,
    runs: usize,
    warmup: usize,
    threads: usize,
    accel: bool,
) -> Result<Timing, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let out = Command::new(exe)
        .env("MILLIEGO_ACCEL", if accel { "1" } else { "0" })
        .arg("--tract-one")
        .arg(path)
        .arg("--inputs")
        .arg(bundle)
        .args(["--runs", &runs.to_string(), "--warmup", &warmup.to_string()])
        .args(["--threads", &threads.to_string()])
        .output()
        .map_err(|e| e.to_string())?;
    if !out.status.success() {
        return Err(format!(
            "tract child failed: {}",
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line).map_err(|e| format!("tract child output {line:?}: {e}"))
}

/// What `milliego_models.ort_bench` prints (the fields used here).
#[derive(Debug, Clone, Deserialize)]
pub struct OrtResult {
    /// `onnxruntime X.Y.Z`.
    pub engine: String,
    /// The fp32 graph.
    pub fp32: Timing,
    /// The int8 file shipped for tract, run by onnxruntime.
    pub tract_int8_file: Timing,
    /// onnxruntime's fastest own int8 variant.
    pub ort_best_int8: OrtBest,
}

/// The best onnxruntime int8 variant.
#[derive(Debug, Clone, Deserialize)]
pub struct OrtBest {
    /// Variant name, e.g. `qdq-u8s8-pertensor`.
    pub variant: String,
    /// Its median latency \[ms\].
    pub median_ms: f64,
    /// Its p99 latency \[ms\].
    pub p99_ms: f64,
    /// Its peak RSS delta \[MB\].
    pub rss_delta_mb: f64,
    /// Max |pose - fp32 pose| on the timed input.
    pub max_abs_diff_vs_fp32: f64,
}

/// The Python interpreter with torch/onnx/onnxruntime: `$MILLIEGO_PYTHON`, else
/// `$MILLIEGO_TORCH_VENV/bin/python`, else `~/.cache/milliego-torch/bin/python`.
pub fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("MILLIEGO_PYTHON") {
        return p.into();
    }
    let venv = std::env::var_os("MILLIEGO_TORCH_VENV")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(std::env::var_os("HOME").unwrap_or_default())
                .join(".cache/milliego-torch")
        });
    venv.join("bin/python")
}

fn py(root: &Path) -> Command {
    let mut c = Command::new(python());
    c.env("PYTHONPATH", root.join("models/python"))
        .env("OMP_NUM_THREADS", "1")
        .env("PYTHONUNBUFFERED", "1");
    c
}

/// Runs `python -m milliego_models.ort_bench` on the fp32 / tract-int8 pair.
pub fn ort_time(
    root: &Path,
    fp32: &Path,
    int8: &Path,
    bundle: &Path,
    runs: usize,
    warmup: usize,
) -> Result<OrtResult, String> {
    let out = py(root)
        .args(["-m", "milliego_models.ort_bench", "--fp32"])
        .arg(fp32)
        .arg("--int8")
        .arg(int8)
        .arg("--inputs")
        .arg(bundle)
        .args(["--runs", &runs.to_string(), "--warmup", &warmup.to_string()])
        .output()
        .map_err(|e| format!("{}: {e}", python().display()))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let tail: Vec<&str> = err.lines().rev().take(3).collect();
        return Err(format!("ort_bench failed: {}", tail.join(" | ")));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().last().unwrap_or_default();
    serde_json::from_str(line).map_err(|e| format!("ort_bench output: {e}"))
}

/// The paper-size graphs in `dir`, generated with `milliego_models.paper_graph` when absent.
/// Returns (fp32, int8).
pub fn paper_graphs(root: &Path, dir: &Path) -> Result<(PathBuf, PathBuf), String> {
    let fp32 = dir.join("milliego-paper-fp32.onnx");
    let int8 = dir.join("milliego-paper-int8.onnx");
    if fp32.is_file() && int8.is_file() {
        return Ok((fp32, int8));
    }
    eprintln!(
        "generating the paper-size graphs into {} (untrained weights, ~1-2 min)",
        dir.display()
    );
    let st = py(root)
        .args(["-m", "milliego_models.paper_graph", "--out"])
        .arg(dir)
        .status()
        .map_err(|e| format!("{}: {e}", python().display()))?;
    if st.success() && fp32.is_file() && int8.is_file() {
        Ok((fp32, int8))
    } else {
        Err(format!("paper_graph failed ({st})"))
    }
}

/// Rows of one graph: tract fp32 / int8 against onnxruntime fp32 / best int8.
pub fn rows(
    group: &str,
    tract_fp32: Result<Timing, String>,
    tract_int8: Result<Timing, String>,
    tract_int8_stock: Result<Timing, String>,
    tract_int8_two_threads: Result<Timing, String>,
    ort: Result<OrtResult, String>,
    note: &str,
) -> Vec<Row> {
    let ms = |t: &Result<Timing, String>, p99: bool| {
        t.as_ref()
            .ok()
            .map(|t| if p99 { t.p99_ms } else { t.median_ms })
    };
    let mb = |t: &Result<Timing, String>| t.as_ref().ok().map(|t| t.rss_delta_mb);
    let o = ort.as_ref().ok();
    let err = [&tract_fp32, &tract_int8]
        .iter()
        .filter_map(|t| t.as_ref().err().cloned())
        .chain(ort.as_ref().err().cloned())
        .collect::<Vec<_>>()
        .join("; ");
    let note = if err.is_empty() {
        note.to_string()
    } else {
        format!("{note} ERR: {err}")
    };
    let best = o
        .map(|o| {
            format!(
                "ORT best int8 ({})",
                o.ort_best_int8.variant.trim_start_matches("qdq-")
            )
        })
        .unwrap_or_else(|| "ORT best int8".into());
    let best_note = o
        .map(|o| {
            format!(
                "ORT variant max pose diff vs fp32 {:.2e}",
                o.ort_best_int8.max_abs_diff_vs_fp32
            )
        })
        .unwrap_or_default();
    let l = Better::Lower;
    let ratio_note = |goal: &str| format!("{goal}{note}");
    let mut v = vec![
        Row::new(
            group,
            "tract fp32 median",
            ms(&tract_fp32, false),
            "ms",
            "ORT fp32",
            o.map(|o| o.fp32.median_ms),
            l,
            &note,
        ),
        Row::new(
            group,
            "tract fp32 p99",
            ms(&tract_fp32, true),
            "ms",
            "ORT fp32",
            o.map(|o| o.fp32.p99_ms),
            l,
            "",
        ),
        Row::new(
            group,
            "tract int8 median",
            ms(&tract_int8, false),
            "ms",
            &best,
            o.map(|o| o.ort_best_int8.median_ms),
            l,
            &ratio_note("goal <= 1.0; "),
        ),
        Row::new(
            group,
            "tract int8 p99",
            ms(&tract_int8, true),
            "ms",
            &best,
            o.map(|o| o.ort_best_int8.p99_ms),
            l,
            &best_note,
        ),
        Row::new(
            group,
            "tract int8 vs tract fp32",
            ms(&tract_int8, false),
            "ms",
            "tract fp32",
            ms(&tract_fp32, false),
            l,
            "int8 speed-up in tract",
        ),
        Row::new(
            group,
            "tract int8, accel passes",
            ms(&tract_int8, false),
            "ms",
            "stock tract plan",
            ms(&tract_int8_stock, false),
            l,
            "milliego-accel (packed im2col, quantize); same values",
        ),
        Row::new(
            group,
            "tract int8, 2 threads",
            ms(&tract_int8_two_threads, false),
            "ms",
            "tract int8, 1 thread",
            ms(&tract_int8, false),
            l,
            "multithreaded matmul (`milliego run --threads 2`); same values",
        ),
        Row::new(
            group,
            "ORT on tract's int8 file",
            o.map(|o| o.tract_int8_file.median_ms),
            "ms",
            &best,
            o.map(|o| o.ort_best_int8.median_ms),
            l,
            "the tract recipe in onnxruntime (informational)",
        ),
        Row::new(
            group,
            "tract fp32 peak RSS delta",
            mb(&tract_fp32),
            "MB",
            "ORT fp32",
            o.map(|o| o.fp32.rss_delta_mb),
            l,
            "load + runs",
        ),
        Row::new(
            group,
            "tract int8 peak RSS delta",
            mb(&tract_int8),
            "MB",
            &best,
            o.map(|o| o.ort_best_int8.rss_delta_mb),
            l,
            "",
        ),
    ];
    if let (Ok(a), Ok(b)) = (&tract_fp32, &tract_int8) {
        let d = a
            .pose
            .iter()
            .zip(&b.pose)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        if let Some(r) = v.get_mut(4) {
            r.notes = format!("int8 speed-up in tract; max pose diff int8 vs fp32 {d:.2e}");
        }
    }
    v
}

/// Where one call of a graph spends its time in tract.
#[derive(Debug, Clone, Default)]
pub struct Profile {
    /// (op type, ms per call summed over its nodes, node count), slowest first.
    pub ops: Vec<(String, f64, usize)>,
    /// (node name, op type and its description, ms per call), the 20 slowest.
    pub nodes: Vec<(String, f64)>,
    /// Median of the whole call \[ms\] (per-node timing included).
    pub median_ms: f64,
}

/// Per-node profile of one optimised graph in tract over `runs` calls (timed around each node's
/// eval through `SimpleState::run_plan_with_eval`).
pub fn profile(
    path: &Path,
    inputs: &Inputs,
    runs: usize,
    threads: usize,
) -> Result<Profile, String> {
    let e = |e: TractError| format!("{e:#}");
    let (mut state, h) = load_state(path, threads)?;
    let plan = state.plan().clone();
    let mk = || feed(inputs, h);
    let mut by_node: std::collections::HashMap<usize, f64> = Default::default();
    let mut whole = Vec::new();
    state.run(mk()?).map_err(e)?;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        state
            .run_plan_with_eval(mk()?, |ctx, st, node, input| {
                let t = Instant::now();
                let r = tract_onnx::tract_core::plan::eval(ctx, st, node, input);
                *by_node.entry(node.id).or_default() += t.elapsed().as_secs_f64() * 1e3;
                r
            })
            .map_err(e)?;
        whole.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let n = runs.max(1) as f64;
    let m = plan.model();
    let mut by_op: std::collections::BTreeMap<String, (f64, usize)> = Default::default();
    let mut nodes = Vec::new();
    for (id, ms) in &by_node {
        let node = m.node(*id);
        let op = node.op().name().to_string();
        let e = by_op.entry(op.clone()).or_default();
        e.0 += ms / n;
        e.1 += 1;
        // The op's own description names the kernel it runs (e.g. the matmul kernel).
        let info = node.op().info().unwrap_or_default().join("; ");
        nodes.push((format!("{} ({op}) {info}", node.name), ms / n));
    }
    let mut ops: Vec<(String, f64, usize)> =
        by_op.into_iter().map(|(k, (t, c))| (k, t, c)).collect();
    ops.sort_by(|a, b| b.1.total_cmp(&a.1));
    nodes.sort_by(|a, b| b.1.total_cmp(&a.1));
    nodes.truncate(20);
    Ok(Profile {
        ops,
        nodes,
        median_ms: percentile(&whole, 50.0).unwrap_or(f64::NAN),
    })
}

fn plan_with_threads(typed: TypedModel, threads: usize) -> Result<Arc<TypedSimplePlan>, String> {
    let mut opts = tract_onnx::tract_core::runtime::RunOptions::default();
    if threads > 1 {
        opts.executor = Some(tract_linalg::multithread::Executor::multithread(threads));
    }
    TypedSimplePlan::new_with_options(typed, &opts).map_err(|e| format!("{e:#}"))
}
