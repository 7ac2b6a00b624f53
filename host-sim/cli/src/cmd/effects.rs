//! `paragyro-sim effects`: the effects the simulator can add (names, units, what they add).

use super::{Ctx, Failure};

/// Prints the effect library and the effects outside it.
pub fn exec(ctx: &mut Ctx) -> Result<(), Failure> {
    let mut text = String::from("Effects the simulator can add (--effect NAME=SIZE):\n");
    for (name, what) in paragyro_simulator::effects::describe() {
        let lib = if paragyro_simulator::effects::LIBRARY.contains(&name) {
            "library"
        } else {
            "outside the library"
        };
        text.push_str(&format!("  {name:<24} {what} [{lib}]\n"));
    }
    ctx.say(&text)
}
