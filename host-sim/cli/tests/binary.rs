//! The built `paragyro-sim` binary (this test makes `cargo test --workspace` build it, into
//! the test profile's directory: `cargo xtask test` hands that binary to the Python tests,
//! host-sim/py/tests, as the CLI they compare with).

use std::process::Command;

use paragyro_simulator::scenario::Scenario;

#[test]
fn the_binary_lists_every_built_in_scenario() {
    let out = Command::new(env!("CARGO_BIN_EXE_paragyro-sim"))
        .arg("list")
        .output()
        .expect("paragyro-sim runs");
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).expect("UTF-8");
    for (name, _) in Scenario::builtin_names() {
        assert!(
            text.lines()
                .any(|l| l.split_whitespace().next() == Some(name)),
            "`{name}` not listed:\n{text}"
        );
    }
}
