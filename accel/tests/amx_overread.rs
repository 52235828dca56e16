//! tract 0.23's AMX int8 kernels read B past its panels (docs/amx-overread.md), pinned at two
//! depths:
//!
//! - the kernel alone (the upstream reproducer): one 16x16 tile with K = 72, B's packed panel
//!   placed so that it ends exactly at a `PROT_NONE` guard page. Without slack the kernel faults
//!   (SIGSEGV); with [`amx_tile_slack`] bytes after the panel it runs, and its result is the exact
//!   integer product whatever those bytes hold (no output depends on bytes outside the buffers).
//!   Each case runs in a child process, since the fault kills the process.
//! - the shipped int8 model: every over-reading B operand of an AMX matmul is padded, with the
//!   speed passes and without them (tract's own `Im2col`), and the guard changes no value.
//!
//! On a machine without AMX int8 the kernel cases print a skip line; the plan case still checks
//! that the guard leaves the plan's values alone.
// mmap/mprotect for the guard page, and tract's kernel API (unsafe by contract), in this test only.
#![allow(unsafe_code)]

use milliego_accel::{amx_nr, amx_tile_slack, guard_amx, prepare};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::path::Path;
use std::process::Command;
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::{bail, DimLike, ExoticFact, TractErrorContext};
use tract_onnx::tract_core::tract_linalg::isa;
use tract_onnx::tract_core::tract_linalg::mmm::{
    AsInputValue, EagerPackedInput, FusedSpec, MMMInputFormat, MMMInputValue, MatMatMul,
    PackedExoticFact,
};
use tract_onnx::tract_core::tract_linalg::mmm_routines::runnable_for;

const KERNEL: &str = "avx512amx_mmm_i32_16x16";
const CHILD: &str = "MILLIEGO_AMX_CHILD";
const M: usize = 16;
const N: usize = 16;
/// Not a multiple of 64: the kernel's last B tile reaches 56 K rows past the panel.
const K: usize = 72;

fn amx_kernel() -> Option<Box<dyn MatMatMul>> {
    runnable_for(&isa::native())
        .into_iter()
        .find(|m| m.name() == KERNEL)
}

/// A packed B whose panel lives at a fixed address (inside a mapping with a guard page).
#[derive(Clone, Debug, Hash, PartialEq, Eq)]
struct Placed {
    fact: PackedExoticFact,
    addr: usize,
    panel_bytes: usize,
    mn: usize,
}

impl std::fmt::Display for Placed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "placed {} at {:#x}", self.fact, self.addr)
    }
}

impl MMMInputValue for Placed {
    fn format(&self) -> &dyn MMMInputFormat {
        &*self.fact.format
    }
    fn scratch_panel_buffer_layout(&self) -> Option<std::alloc::Layout> {
        None
    }
    fn panel_bytes(&self, i: usize, _: Option<*mut u8>) -> TractResult<*const u8> {
        Ok((self.addr + i * self.panel_bytes) as *const u8)
    }
    fn mn(&self) -> usize {
        self.mn
    }
    fn k(&self) -> usize {
        self.fact.k
    }
    fn exotic_fact(&self) -> &dyn ExoticFact {
        &self.fact
    }
    fn extract_at_mn_f16(&self, _: usize, _: &mut [f16]) -> TractResult<()> {
        bail!("not needed")
    }
    fn extract_at_mn_f32(&self, _: usize, _: &mut [f32]) -> TractResult<()> {
        bail!("not needed")
    }
}

/// `len` bytes that end exactly where a `PROT_NONE` page begins.
struct Guarded {
    base: *mut libc::c_void,
    map_len: usize,
    start: *mut u8,
}

impl Guarded {
    fn new(len: usize) -> Guarded {
        let page = 4096;
        let data_pages = len.div_ceil(page);
        let map_len = (data_pages + 1) * page;
        unsafe {
            let base = libc::mmap(
                std::ptr::null_mut(),
                map_len,
                libc::PROT_READ | libc::PROT_WRITE,
                libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
                -1,
                0,
            );
            assert_ne!(base, libc::MAP_FAILED, "mmap");
            let guard = (base as *mut u8).add(data_pages * page);
            assert_eq!(
                libc::mprotect(guard as *mut libc::c_void, page, libc::PROT_NONE),
                0
            );
            Guarded {
                base,
                map_len,
                start: guard.sub(len),
            }
        }
    }
}

impl Drop for Guarded {
    fn drop(&mut self) {
        unsafe {
            libc::munmap(self.base, self.map_len);
        }
    }
}

/// The child's work: one AMX matmul with B ending at the guard page, `slack` bytes after the
/// panel filled with `fill`. Prints the max difference to the integer product.
fn child(slack: usize, fill: u8) {
    let mmm = amx_kernel().expect("the parent checked AMX");
    let mut rng = StdRng::seed_from_u64(7);
    let a: Vec<i8> = (0..M * K).map(|_| rng.gen()).collect();
    let b: Vec<i8> = (0..K * N).map(|_| rng.gen()).collect();
    let ta = Tensor::from_shape(&[M, K], &a).unwrap();
    let tb = Tensor::from_shape(&[K, N], &b).unwrap();
    let (pack_a, pack_b) = &mmm.packings()[1];
    let pa = pack_a.prepare_one(&ta, 1, 0).unwrap();
    let pb = pack_b.prepare_one(&tb, 0, 1).unwrap();
    let eager = pb.downcast_ref::<EagerPackedInput>().expect("eager B");
    let bytes = eager.packed.as_bytes();
    let mem = Guarded::new(bytes.len() + slack);
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), mem.start, bytes.len());
        std::ptr::write_bytes(mem.start.add(bytes.len()), fill, slack);
    }
    let placed = Placed {
        fact: eager.fact.clone(),
        addr: mem.start as usize,
        panel_bytes: eager.panel_bytes,
        mn: eager.mn,
    };
    let mut c = Tensor::zero::<i32>(&[M, N]).unwrap();
    unsafe {
        let store = mmm.c_view(Some(0), Some(1)).wrap(&c.view_mut());
        mmm.run(
            M,
            N,
            &[
                FusedSpec::AddMatMul {
                    a: AsInputValue::Borrowed(&*pa),
                    b: AsInputValue::Borrowed(&placed),
                    packing: 1,
                },
                FusedSpec::Store(store),
            ],
        )
        .unwrap();
    }
    let c: Vec<i32> = c
        .to_plain_array_view::<i32>()
        .unwrap()
        .iter()
        .copied()
        .collect();
    let mut worst = 0i64;
    for i in 0..M {
        for j in 0..N {
            let want: i32 = (0..K)
                .map(|k| i32::from(a[i * K + k]) * i32::from(b[k * N + j]))
                .sum();
            worst = worst.max((i64::from(c[i * N + j]) - i64::from(want)).abs());
        }
    }
    println!("AMX-CHILD max-diff {worst}");
}

/// Runs [`child_entry`] in a child process with `mode`; its exit status and output.
fn run_child(mode: &str) -> (std::process::ExitStatus, String) {
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_entry", "--nocapture", "--test-threads=1"])
        .env(CHILD, mode)
        .output()
        .expect("spawn the test binary");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status, text)
}

/// Not a test of its own: the body of the child processes (does nothing unless asked to).
#[test]
fn child_entry() {
    let Ok(mode) = std::env::var(CHILD) else {
        return;
    };
    let slack = amx_tile_slack(K, N);
    match mode.as_str() {
        "exact" => child(0, 0),
        "zeros" => child(slack, 0),
        "garbage" => child(slack, 0x7f),
        "plan" => plan_child(),
        m => panic!("unknown mode {m}"),
    }
}

/// Under a forced AMX instruction set: plans the shipped int8 model with and without the speed
/// passes, guards it, and checks every over-reading B operand of an AMX matmul has its slack.
/// Plans only: the kernels may not run on this CPU.
fn plan_child() {
    use tract_onnx::tract_core::ops::matmul::optimized::{
        MatMulOperand, OptMatMul, ProtoFusedSpec,
    };
    for accel in [true, false] {
        let (mut typed, _) = int8_model(accel).unwrap();
        let g = guard_amx(&mut typed).unwrap();
        let mut checked = 0;
        for node in typed.nodes() {
            let Some(op) = node.op_as::<OptMatMul>() else {
                continue;
            };
            let Some(nr) = amx_nr(op) else {
                continue;
            };
            for spec in &op.micro_ops {
                if let ProtoFusedSpec::AddMatMul {
                    geo,
                    b: MatMulOperand::Input(slot),
                    ..
                } = spec
                {
                    let k = geo.k.to_usize().unwrap();
                    if amx_tile_slack(k, nr) == 0 {
                        continue;
                    }
                    let producer = typed.node(node.inputs[*slot].node);
                    let name = producer.op.name();
                    assert!(
                        name == "PackedIm2col" || name == "PanelSlack",
                        "{}: B (k={k}) from {} ({name}) has no slack",
                        node.name,
                        producer.name
                    );
                    checked += 1;
                }
            }
        }
        println!("AMX-PLAN accel={accel} checked={checked} {g}");
    }
}

#[test]
fn amx_kernel_reads_past_the_panel_and_slack_makes_it_safe() {
    if amx_kernel().is_none() {
        println!("skipped: {KERNEL} does not run on this machine (no AMX int8)");
        return;
    }
    // K = 72 with K=4 padding is an 18-row panel of 64 B; the kernel loads 2 tiles of 16 rows.
    assert_eq!(amx_tile_slack(K, N), (128 - 72) * 16);
    for mode in ["zeros", "garbage"] {
        let (status, text) = run_child(mode);
        assert!(status.success(), "{mode}: {status}\n{text}");
        assert!(
            text.contains("AMX-CHILD max-diff 0"),
            "{mode}: the result depends on the bytes past the panel\n{text}"
        );
    }
    let (status, text) = run_child("exact");
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        assert_eq!(
            status.signal(),
            Some(libc::SIGSEGV),
            "{KERNEL} no longer reads past a K=72 panel (status {status}): tract fixed the \
             over-read; the guard in milliego-accel can go\n{text}"
        );
    }
}

/// The guard's plan on a CPU that has AMX, planned anywhere: `TRACT_CPU_ISA` adds AMX int8 (and
/// the AVX-512 levels it sits on) to what tract dispatches for, in a child process.
#[test]
fn the_guard_pads_every_amx_operand_of_the_planned_model() {
    // tract evaluates small subgraphs while it optimises, with the kernels of the instruction set
    // it was told about: planning for AMX needs a CPU that runs AVX-512 (VNNI) itself.
    if !(std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vnni")) {
        println!(
            "skipped: planning for AMX needs AVX-512F and AVX-512 VNNI on this CPU (tract evaluates \
             constant subgraphs with them while optimising)"
        );
        return;
    }
    let out = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_entry", "--nocapture", "--test-threads=1"])
        .env(CHILD, "plan")
        .env("TRACT_CPU_ISA", "+avx512f,+avx512vnni,+amx-int8")
        .env("TRACT_AVX512_FMA_UNITS", "1")
        .output()
        .expect("spawn the test binary");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{}\n{text}", out.status);
    // libtest writes `test child_entry ... ` before the test's own output on the same line.
    let lines: Vec<&str> = text
        .lines()
        .filter_map(|l| l.find("AMX-PLAN").map(|i| &l[i..]))
        .collect();
    println!("{}", lines.join("\n"));
    assert_eq!(lines.len(), 2, "{text}");
    for l in lines {
        let checked: usize = l
            .split_whitespace()
            .find_map(|w| w.strip_prefix("checked="))
            .and_then(|n| n.parse().ok())
            .unwrap();
        assert!(checked > 0, "no over-reading AMX operand planned: {l}");
    }
}

/// `PanelSlack` (what the guard puts after producers it does not control) keeps every panel
/// byte, batch layout and fact, and adds exactly the zeroed slack. Runs on any CPU (packing only).
#[test]
fn panel_slack_keeps_the_panels_and_adds_zeroed_slack() -> TractResult<()> {
    use milliego_accel::PanelSlack;
    use tract_onnx::tract_core::internal::{EvalContext, EvalOp, TypedOp};
    use tract_onnx::tract_core::tract_linalg::mmm::PackedMatrixStorage;
    use tract_onnx::tract_core::tract_linalg::pack::PackedI8K4;
    let mut rng = StdRng::seed_from_u64(5);
    let (k, n, r) = (72, 40, 16);
    let format = PackedI8K4::new(r);
    let values = (0..2)
        .map(|_| {
            let v: Vec<i8> = (0..k * n).map(|_| rng.gen()).collect();
            format.prepare_one(&Tensor::from_shape(&[k, n], &v)?, 0, 1)
        })
        .collect::<TractResult<TVec<_>>>()?;
    let input = PackedMatrixStorage::new_batched(&[1, 2], values).into_tensor(i8::datum_type());
    let slack = amx_tile_slack(k, r);
    let op = PanelSlack { slack };
    let fact = i8::fact([1, 2]);
    assert_eq!(op.output_facts(&[&fact])?[0], fact);
    let out = EvalOp::eval(
        &op,
        &EvalContext::out_of_plan(),
        tvec!(input.clone().into_tvalue()),
    )?;
    let (a, b) = (
        input.try_storage_as::<PackedMatrixStorage>()?,
        out[0].try_storage_as::<PackedMatrixStorage>()?,
    );
    assert_eq!(a.batch_shape(), b.batch_shape());
    for (x, y) in a.values().iter().zip(b.values()) {
        let x = x.downcast_ref::<EagerPackedInput>().unwrap();
        let y = y.downcast_ref::<EagerPackedInput>().unwrap();
        let (bx, by) = (x.packed.as_bytes(), y.packed.as_bytes());
        assert_eq!(bx.len() + slack, by.len());
        assert_eq!(bx, &by[..bx.len()]);
        assert!(by[bx.len()..].iter().all(|&v| v == 0));
        assert_eq!(
            (x.panel_bytes, x.mn, x.fact.k),
            (y.panel_bytes, y.mn, y.fact.k)
        );
        assert_eq!(y.packed.as_ptr() as usize % 64, 0, "cache-line aligned");
    }
    Ok(())
}

fn int8_path() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/compact/model-int8.onnx")
}

fn int8_model(accel: bool) -> TractResult<(TypedModel, usize)> {
    let h = hidden_of(&int8_path())?;
    let mut model = tract_onnx::onnx().model_for_path(int8_path())?;
    for (i, s) in [vec![1, 6, 64, 256], vec![1, 20, 6], vec![1, 4, h]]
        .iter()
        .enumerate()
    {
        model.set_input_fact(i, f32::fact(s.as_slice()).into())?;
    }
    let mut typed = model.into_optimized()?;
    if accel {
        milliego_accel::accelerate(&mut typed)?;
    }
    Ok((typed, h))
}

fn amx_b_operands(m: &TypedModel) -> usize {
    m.nodes()
        .iter()
        .filter_map(|n| n.op_as::<tract_onnx::tract_core::ops::matmul::optimized::OptMatMul>())
        .filter(|op| amx_nr(op).is_some())
        .count()
}

fn outputs(m: TypedModel, h: usize, seed: u64) -> TractResult<Vec<Vec<f32>>> {
    let plan = m.into_runnable()?;
    let mut rng = StdRng::seed_from_u64(seed);
    let mut input = |s: &[usize]| {
        let n: usize = s.iter().product();
        let v: Vec<f32> = (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        Tensor::from_shape(s, &v).map(|t| t.into_tvalue())
    };
    let feed = tvec!(
        input(&[1, 6, 64, 256])?,
        input(&[1, 20, 6])?,
        input(&[1, 4, h])?
    );
    plan.run(feed)?
        .iter()
        .map(|t| {
            t.to_plain_array_view::<f32>()
                .map(|v| v.iter().copied().collect())
        })
        .collect()
}

#[test]
fn shipped_int8_model_has_every_amx_b_operand_padded() -> TractResult<()> {
    for accel in [true, false] {
        let (mut typed, h) = int8_model(accel)?;
        let reference = outputs(typed.clone(), h, 3)?;
        let g = guard_amx(&mut typed)?;
        println!("speed passes {accel}: {g}");
        assert_eq!(
            g.already_safe + g.slack_ops + g.consts_padded,
            g.overreading,
            "{g}"
        );
        if amx_b_operands(&typed) > 0 {
            assert!(g.amx_matmuls > 0 && g.overreading > 0, "{g}");
            // With the speed passes the packed im2col carries the slack itself: no copies.
            if accel {
                assert_eq!(g.slack_ops, 0, "{g}");
            } else {
                assert!(g.slack_ops > 0, "{g}");
            }
        }
        assert_eq!(
            outputs(typed, h, 3)?,
            reference,
            "the guard changed a value"
        );
    }
    // `prepare` (what Model::load runs) applies the guard too.
    let (mut typed, _) = int8_model(false)?;
    let p = prepare(&mut typed)?;
    assert_eq!(
        p.amx.already_safe + p.amx.slack_ops + p.amx.consts_padded,
        p.amx.overreading
    );
    Ok(())
}

/// The model's LSTM width, from its `milliego` metadata entry.
fn hidden_of(path: &Path) -> TractResult<usize> {
    let proto = tract_onnx::onnx().proto_model_for_path(path)?;
    let meta = proto
        .metadata_props
        .iter()
        .find(|p| p.key == "milliego")
        .context("no milliego metadata")?;
    let key = "\"hidden\":";
    let at = meta.value.find(key).context("no hidden size")? + key.len();
    let digits: String = meta.value[at..]
        .trim_start()
        .chars()
        .take_while(char::is_ascii_digit)
        .collect();
    Ok(digits.parse()?)
}
