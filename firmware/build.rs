//! Puts memory.x (LM3S6965: 256 KiB flash, 64 KiB SRAM) and an empty device.x (the vector
//! table is defined in main.rs) where cortex-m-rt's link.x finds them.
use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR"));
    fs::write(out.join("memory.x"), include_bytes!("memory.x")).expect("memory.x");
    fs::write(
        out.join("device.x"),
        b"/* interrupts: __INTERRUPTS in src/main.rs */\n",
    )
    .expect("device.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
}
