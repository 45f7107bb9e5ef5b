//! Picks the memory map of the selected board and exposes it to the linker as
//! `memory-map.x`, which the workspace-root `memory.x` INCLUDEs (a full map in
//! the root would shadow this choice: notes/embedded-feasibility.md, pitfall 1).

use std::{env, fs, path::PathBuf};

fn main() {
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    let dir =
        PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"));
    let nucleo = env::var_os("CARGO_FEATURE_NUCLEO_G474RE").is_some();
    let qemu = env::var_os("CARGO_FEATURE_MPS2_AN386").is_some();
    // The host build (clippy on the workspace) needs no map; the firmware build
    // without exactly one board fails in src/board/mod.rs with a clear message.
    let map = match (nucleo, qemu) {
        (true, false) => Some("nucleo-g474re.x"),
        (false, true) => Some("mps2-an386.x"),
        _ => None,
    };
    if let Some(map) = map {
        let src = dir.join("memory").join(map);
        fs::copy(&src, out.join("memory-map.x")).expect("copy the board's memory map");
        println!("cargo:rustc-link-search={}", out.display());
        println!("cargo:rerun-if-changed={}", src.display());
    }
    // The root memory.x is read by the linker from the workspace root; relink
    // when it changes.
    println!(
        "cargo:rerun-if-changed={}",
        dir.join("../../memory.x").display()
    );
    println!("cargo:rerun-if-changed=memory");
    println!("cargo:rerun-if-changed=build.rs");
}
