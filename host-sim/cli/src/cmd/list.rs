//! `paragyro-sim list`: the built-in scenarios.

use super::{Ctx, Failure};
use paragyro_simulator::scenario::Scenario;

/// Prints the built-in scenarios with their descriptions.
pub fn exec(ctx: &mut Ctx) -> Result<(), Failure> {
    let list = Scenario::builtin_names();
    let width = list.iter().map(|(n, _)| n.len()).max().unwrap_or(0);
    let mut text =
        String::from("Built-in scenarios (run with `paragyro-sim run <name> --out DIR`):\n");
    for (name, desc) in list {
        text.push_str(&format!("  {name:<width$}  {desc}\n"));
    }
    text.push_str("Or pass a scenario file (TOML, schema in host-sim/scenarios/README.md).\n");
    ctx.say(&text)
}
