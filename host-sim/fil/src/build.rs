//! Builds what a session needs: the `fil` firmware image and the instruction-count plugin.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{Context, ensure};

/// The workspace root (two levels above this crate).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .ancestors()
        .nth(2)
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// `cargo build -p paragyro-firmware --target thumbv7em-none-eabihf --release
/// --no-default-features --features fil` in `target_dir` (its own, so that it never
/// relinks another board's image under a running test), then copies the image to
/// `out/paragyro-firmware-fil.elf`.
pub fn firmware(target_dir: &Path, out: &Path) -> anyhow::Result<PathBuf> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(workspace_root())
        .env("CARGO_TARGET_DIR", target_dir)
        .args([
            "build",
            "-q",
            "-p",
            "paragyro-firmware",
            "--target",
            "thumbv7em-none-eabihf",
            "--release",
            "--no-default-features",
            "--features",
            "fil",
        ])
        .status()
        .context("running cargo to build the fil firmware")?;
    ensure!(
        status.success(),
        "building the fil firmware failed (is the thumbv7em-none-eabihf target installed? `cargo xtask setup`)"
    );
    std::fs::create_dir_all(out)?;
    let elf = out.join("paragyro-firmware-fil.elf");
    std::fs::copy(
        target_dir.join("thumbv7em-none-eabihf/release/paragyro-firmware"),
        &elf,
    )
    .context("copying the fil firmware image")?;
    Ok(elf)
}

/// Compiles firmware/tools/tickcount.c into `out/libtickcount.so` with the system's C
/// compiler (`cc`, which Rust's host linking needs anyway).
pub fn plugin(out: &Path) -> anyhow::Result<PathBuf> {
    std::fs::create_dir_all(out)?;
    let so = out.join("libtickcount.so");
    let src = workspace_root().join("firmware/tools/tickcount.c");
    let status = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()))
        .args(["-shared", "-fPIC", "-O2", "-o"])
        .arg(&so)
        .arg(&src)
        .status()
        .context("running cc to build the QEMU plugin")?;
    ensure!(status.success(), "compiling {} failed", src.display());
    Ok(so)
}
