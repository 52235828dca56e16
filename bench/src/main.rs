//! `milliego-bench [--json FILE] [--quick] [--paper-dir DIR] [--e2e CMD]...`: the whole table.
//! `milliego-bench --profile MODEL [--threads N]`: per-op-type time of one graph in tract.
//! `milliego-bench --tract-one MODEL --inputs BUNDLE`: one graph's tract timing as JSON (used as
//! a child process by the table, so each graph's peak RSS delta is its own).

use clap::Parser;
use milliego_bench::decode::{self, Reps};
use milliego_bench::{e2e, format_table, infer, Machine, Report, Row};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

#[derive(Debug, Parser)]
#[command(about = "milliEgo benchmarks side by side with their peers (one table, one run)")]
struct Args {
    /// Also write every row and the machine info as JSON to FILE.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Fewer repetitions (CI smoke run; figures are noisier).
    #[arg(long)]
    quick: bool,
    /// Paper-size graphs (generated with `python -m milliego_models.paper_graph` when absent).
    #[arg(long)]
    paper_dir: Option<PathBuf>,
    /// Shell command printing a JSON summary of `milliego run` (end-to-end rows); repeat it for
    /// several (e.g. `--e2e 'scripts/e2e-latency model' --e2e 'scripts/e2e-latency doppler --view'`).
    #[arg(long)]
    e2e: Vec<String>,
    /// Skip the paper-size graph (it needs the Python venv to generate and ~1 min to time).
    #[arg(long)]
    no_paper: bool,
    /// Timed inference runs per graph and engine (default 100, 10 with --quick).
    #[arg(long)]
    runs: Option<usize>,
    /// Print the per-op-type profile of MODEL in tract and exit.
    #[arg(long, value_name = "MODEL")]
    profile: Option<PathBuf>,
    /// tract threads for --profile and --tract-one.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Time MODEL in tract and print its timing as one JSON line (child-process mode).
    #[arg(long, value_name = "MODEL")]
    tract_one: Option<PathBuf>,
    /// Input bundle (radar_0, imu_0, state_0); default models/compact/golden.safetensors.
    #[arg(long)]
    inputs: Option<PathBuf>,
    /// Warm-up runs before timing.
    #[arg(long)]
    warmup: Option<usize>,
}

fn root() -> PathBuf {
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    here.parent().map(PathBuf::from).unwrap_or(here)
}

fn milliego_binary(root: &Path) -> PathBuf {
    let sibling = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join("milliego")));
    match sibling {
        Some(p) if p.is_file() => p,
        _ => root.join("target/release/milliego"),
    }
}

fn load(m: &Machine) -> String {
    m.load_avg_1m
        .map_or("unknown".into(), |l| format!("{l:.2}"))
}

fn main() -> ExitCode {
    let a = Args::parse();
    let root = root();
    let compact = root.join("models/compact");
    let bundle = a
        .inputs
        .clone()
        .unwrap_or_else(|| compact.join("golden.safetensors"));
    let runs = a.runs.unwrap_or(if a.quick { 10 } else { 100 });
    let warmup = a.warmup.unwrap_or(if a.quick { 2 } else { 5 });

    if let Some(model) = &a.tract_one {
        let r = infer::load_inputs(&bundle)
            .and_then(|i| infer::tract_time(model, &i, runs, warmup, a.threads));
        return match r {
            Ok(t) => {
                println!("{}", serde_json::to_string(&t).unwrap_or_default());
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("{e}");
                ExitCode::FAILURE
            }
        };
    }
    if let Some(model) = &a.profile {
        let r = infer::load_inputs(&bundle)
            .and_then(|i| infer::profile(model, &i, runs.min(50), a.threads));
        return match r {
            Ok(infer::Profile {
                ops,
                nodes,
                median_ms: whole,
            }) => {
                let total: f64 = ops.iter().map(|o| o.1).sum();
                println!(
                    "{} in tract, {} thread(s): median {whole:.2} ms per call, sum of nodes {total:.2} ms",
                    model.display(),
                    a.threads
                );
                println!(
                    "{:<28} {:>9} {:>6} {:>6}",
                    "op type", "ms/call", "share", "nodes"
                );
                for (op, ms, n) in &ops {
                    println!(
                        "{op:<28} {ms:>9.3} {:>5.1}% {n:>6}",
                        100.0 * ms / total.max(1e-9)
                    );
                }
                println!("\nslowest nodes:");
                for (name, ms) in &nodes {
                    println!("{ms:>9.3} ms  {name}");
                }
                ExitCode::SUCCESS
            }
            Err(e) => {
                eprintln!("{e}");
                ExitCode::FAILURE
            }
        };
    }

    let machine = Machine::detect();
    eprintln!(
        "milliego-bench on {} ({} cores, load average {}){}",
        machine.cpu,
        machine.cores,
        load(&machine),
        if a.quick { ", --quick" } else { "" }
    );
    let reps = if a.quick {
        Reps {
            rounds: 1,
            min: Duration::from_millis(20),
        }
    } else {
        Reps {
            rounds: 5,
            min: Duration::from_millis(150),
        }
    };
    let mut rows: Vec<Row> = Vec::new();
    eprintln!("decoders ...");
    rows.extend(decode::radar_rows(reps));
    rows.extend(decode::imu_rows(reps));

    let mut graphs = vec![(
        "inference: compact model (trained), batch 1, 1 thread".to_string(),
        Ok((compact.join("model.onnx"), compact.join("model-int8.onnx"))),
        String::new(),
    )];
    if !a.no_paper {
        let dir = a
            .paper_dir
            .clone()
            .unwrap_or_else(|| root.join("target/bench-models/paper"));
        graphs.push((
            "inference: paper-size graph (UNTRAINED weights), batch 1, 1 thread".to_string(),
            infer::paper_graphs(&root, &dir),
            "untrained weights: speed only; ".to_string(),
        ));
    }
    for (group, files, note) in graphs {
        eprintln!("{group} ...");
        let (fp32, int8) = match files {
            Ok(f) => f,
            Err(e) => {
                rows.push(Row::missing(&group, "all", &format!("n/a ({e})")));
                continue;
            }
        };
        let t32 = infer::tract_time_child(&fp32, &bundle, runs, warmup, 1, true);
        let t8 = infer::tract_time_child(&int8, &bundle, runs, warmup, 1, true);
        // The same int8 plan without milliego-accel's passes: what they buy, in the same run.
        let t8_stock = infer::tract_time_child(&int8, &bundle, runs, warmup, 1, false);
        // Two threads: what a board with a core to spare gains (`milliego run --threads 2`).
        let t8_two = infer::tract_time_child(&int8, &bundle, runs, warmup, 2, true);
        let ort = infer::ort_time(&root, &fp32, &int8, &bundle, runs, warmup);
        rows.extend(infer::rows(&group, t32, t8, t8_stock, t8_two, ort, &note));
    }
    if a.e2e.is_empty() {
        rows.extend(e2e::rows(&milliego_binary(&root), None));
    }
    for cmd in &a.e2e {
        rows.extend(e2e::rows(&milliego_binary(&root), Some(cmd)));
    }

    print!("{}", format_table(&rows));
    println!(
        "machine: {}, {} cores, load average {} at start, {}",
        machine.cpu,
        machine.cores,
        load(&machine),
        machine.date
    );
    if let Some(path) = &a.json {
        let report = Report::new(machine, a.quick, rows);
        let dir = path.parent().filter(|d| !d.as_os_str().is_empty());
        if let Err(e) = dir
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|()| std::fs::write(path, report.to_json()))
        {
            eprintln!("{}: {e}", path.display());
            return ExitCode::FAILURE;
        }
        eprintln!("wrote {}", path.display());
    }
    ExitCode::SUCCESS
}
