use std::{env, fs, path::PathBuf};
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("CARGO_CFG_TARGET_OS").unwrap_or_default() != "none" {
        return;
    }
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    let memory_x = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap()).join("../memory.x");
    fs::copy(&memory_x, out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    // identical code folding (executable sections only, so defmt's tables are untouched):
    // ~340 B of the stm32f405 image (firmware/README.md, "Budgets")
    println!("cargo:rustc-link-arg-bins=--icf=all");
}
