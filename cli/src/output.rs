//! Output plumbing shared by the dump commands: where to write, and in which format.

use clap::ValueEnum;
use std::io::{self, BufWriter, Write};

/// Record format of a dump.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Format {
    /// One JSON object per line.
    Jsonl,
    /// Comma-separated values with a header line.
    Csv,
}

/// Buffered stdout that treats a closed pipe (`| head`) as a normal end, not an error.
pub fn stdout() -> BufWriter<io::StdoutLock<'static>> {
    BufWriter::with_capacity(1 << 16, io::stdout().lock())
}

/// True when the error only means the reader of our output went away.
pub fn is_broken_pipe(e: &io::Error) -> bool {
    e.kind() == io::ErrorKind::BrokenPipe
}

/// Writes one line, mapping a broken pipe to `Ok(false)` ("stop writing").
pub fn line(out: &mut impl Write, text: &str) -> io::Result<bool> {
    match writeln!(out, "{text}") {
        Ok(()) => Ok(true),
        Err(e) if is_broken_pipe(&e) => Ok(false),
        Err(e) => Err(e),
    }
}
