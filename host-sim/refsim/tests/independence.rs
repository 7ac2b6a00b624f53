//! The generator shares no code with the project's simulator, diagnosis or core: its
//! library depends on none of them, and no source file names them.

#[test]
fn the_library_depends_on_no_paragyro_crate() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
    let deps = manifest
        .split("[dependencies]")
        .nth(1)
        .unwrap()
        .split("\n[")
        .next()
        .unwrap();
    assert!(
        !deps.contains("paragyro"),
        "[dependencies] names a paragyro crate:\n{deps}"
    );
    let mut files = 0;
    for e in std::fs::read_dir(dir.join("src")).unwrap() {
        let p = e.unwrap().path();
        let text = std::fs::read_to_string(&p).unwrap();
        files += 1;
        for f in [
            "paragyro_simulator",
            "paragyro_diagnose",
            "paragyro_core",
            "paragyro-",
        ] {
            let hits: Vec<&str> = text
                .lines()
                .filter(|l| l.contains(f) && !l.contains("paragyro-refsim"))
                .filter(|l| !l.contains("paragyro-record"))
                .collect();
            assert!(hits.is_empty(), "{} names {f}: {hits:?}", p.display());
        }
    }
    assert!(files >= 8, "{files} source files");
}
