//! Helpers shared by the integration tests of the milliEgo workspace.
//!
//! * [`captures_dir`] finds the real device captures (never copied into this repository).
//! * [`SeededChunks`] cuts a byte stream into random-sized chunks reproducibly, so a framer can be
//!   fed the way a serial port delivers data.

use rand::{rngs::StdRng, Rng, SeedableRng};
use std::path::PathBuf;

/// Environment variable that overrides where the captures live (the directory holding
/// `ti-mmwave/` and `xsens/`).
pub const CAPTURES_ENV: &str = "MILLIEGO_CAPTURES";

/// Directory of one capture family (`"ti-mmwave"` or `"xsens"`), or `None` with a printed
/// `skipped: captures not found at ...` line when it is absent.
///
/// Looked up, in order: `$MILLIEGO_CAPTURES/<family>`, then `../shared/captures/<family>`
/// relative to the workspace root.
pub fn captures_dir(family: &str) -> Option<PathBuf> {
    let root = match std::env::var_os(CAPTURES_ENV) {
        Some(p) => PathBuf::from(p),
        None => workspace_root().join("../shared/captures"),
    };
    let dir = root.join(family);
    if dir.is_dir() {
        Some(dir)
    } else {
        println!(
            "skipped: captures not found at {} (set {CAPTURES_ENV} to the directory holding {family}/)",
            dir.display()
        );
        None
    }
}

/// The workspace root (the parent of this crate's directory).
pub fn workspace_root() -> PathBuf {
    let here = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    here.parent().map(PathBuf::from).unwrap_or(here)
}

/// Splits a byte slice into chunks of random length in `1..=max_chunk`, reproducibly for a seed.
#[derive(Debug)]
pub struct SeededChunks<'a> {
    rest: &'a [u8],
    rng: StdRng,
    max_chunk: usize,
}

impl<'a> SeededChunks<'a> {
    /// Chunks of `data`, each 1 to `max_chunk` bytes long (`max_chunk` is raised to at least 1).
    pub fn new(data: &'a [u8], seed: u64, max_chunk: usize) -> Self {
        Self {
            rest: data,
            rng: StdRng::seed_from_u64(seed),
            max_chunk: max_chunk.max(1),
        }
    }
}

impl<'a> Iterator for SeededChunks<'a> {
    type Item = &'a [u8];
    fn next(&mut self) -> Option<&'a [u8]> {
        if self.rest.is_empty() {
            return None;
        }
        let n = self.rng.gen_range(1..=self.max_chunk).min(self.rest.len());
        let (head, tail) = self.rest.split_at(n);
        self.rest = tail;
        Some(head)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunks_cover_input_exactly_and_repeat_for_a_seed() {
        let data: Vec<u8> = (0..=255u8).cycle().take(10_000).collect();
        let a: Vec<&[u8]> = SeededChunks::new(&data, 7, 300).collect();
        let b: Vec<&[u8]> = SeededChunks::new(&data, 7, 300).collect();
        assert_eq!(a, b);
        assert_eq!(a.concat(), data);
        assert!(a.iter().all(|c| !c.is_empty() && c.len() <= 300));
        let c: Vec<&[u8]> = SeededChunks::new(&data, 8, 300).collect();
        assert_ne!(a, c, "another seed cuts differently");
    }
}
