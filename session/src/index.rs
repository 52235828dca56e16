//! The timing index: when each read chunk of a stream arrived.
//!
//! Layout (little-endian): 16-byte header `MEGOIDX1` + u64 flags (0), then one 16-byte record per
//! chunk: u64 host time \[ns since session start\], u64 end offset (bytes of the data file up to and
//! including this chunk). Host times never decrease; end offsets strictly increase.

use crate::{err, io_err, ErrorKind, SessionError};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// First 8 bytes of an index file.
pub const INDEX_MAGIC: [u8; 8] = *b"MEGOIDX1";

/// One read chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexEntry {
    /// Host monotonic time when the read returned \[ns since session start\].
    pub host_ns: u64,
    /// Bytes of the data file up to and including this chunk \[B\].
    pub end: u64,
}

/// Reads and validates an index file.
pub fn read_index(path: &Path) -> Result<Vec<IndexEntry>, SessionError> {
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    let bad = |m: String| err(path, ErrorKind::Index(m));
    if bytes.len() < 16 || bytes[..8] != INDEX_MAGIC {
        return Err(bad("missing the MEGOIDX1 header".into()));
    }
    let body = &bytes[16..];
    if body.len() % 16 != 0 {
        return Err(bad(format!(
            "{} B of records is not a whole number of 16-byte records",
            body.len()
        )));
    }
    let mut out = Vec::with_capacity(body.len() / 16);
    let mut prev = IndexEntry { host_ns: 0, end: 0 };
    for (i, r) in body.chunks_exact(16).enumerate() {
        let host_ns = u64::from_le_bytes(r[..8].try_into().unwrap_or([0; 8]));
        let end = u64::from_le_bytes(r[8..].try_into().unwrap_or([0; 8]));
        if host_ns < prev.host_ns {
            return Err(bad(format!(
                "record {i}: host time {host_ns} ns goes back from {} ns",
                prev.host_ns
            )));
        }
        if end <= prev.end {
            return Err(bad(format!(
                "record {i}: end offset {end} does not advance past {}",
                prev.end
            )));
        }
        prev = IndexEntry { host_ns, end };
        out.push(prev);
    }
    Ok(out)
}

/// Appends records to an index file.
#[derive(Debug)]
pub struct IndexWriter {
    out: BufWriter<File>,
    path: PathBuf,
}

impl IndexWriter {
    /// Creates the file and writes its header.
    pub fn create(path: &Path) -> Result<IndexWriter, SessionError> {
        let f = File::create(path).map_err(io_err(path))?;
        let mut out = BufWriter::new(f);
        out.write_all(&INDEX_MAGIC).map_err(io_err(path))?;
        out.write_all(&0u64.to_le_bytes()).map_err(io_err(path))?;
        Ok(IndexWriter {
            out,
            path: path.to_path_buf(),
        })
    }

    /// Appends one record.
    pub fn push(&mut self, e: IndexEntry) -> Result<(), SessionError> {
        self.out
            .write_all(&e.host_ns.to_le_bytes())
            .map_err(io_err(&self.path))?;
        self.out
            .write_all(&e.end.to_le_bytes())
            .map_err(io_err(&self.path))
    }

    /// Flushes to disk.
    pub fn finish(mut self) -> Result<(), SessionError> {
        self.out.flush().map_err(io_err(&self.path))?;
        self.out.get_ref().sync_all().map_err(io_err(&self.path))
    }
}
