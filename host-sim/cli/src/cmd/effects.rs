//! `paragyro-sim effects`: the effects the simulator can add (names, units, what they add).

use super::{Ctx, Failure};
use paragyro_simulator::effects::Effect;

/// Prints the effect library and the effects outside it.
pub fn exec(ctx: &mut Ctx) -> Result<(), Failure> {
    let mut text = String::from("Effects the simulator can add (--effect NAME=SIZE):\n");
    for e in Effect::ALL {
        let lib = if e.in_library() {
            "library"
        } else {
            "outside the library"
        };
        text.push_str(&format!("  {:<24} {} [{lib}]\n", e.name(), e.describe()));
    }
    ctx.say(&text)
}
