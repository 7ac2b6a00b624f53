//! `paragyro-sim paper-claims`: seed 000's "sense amplitude drops to 20 %" claim, reading
//! by reading (full-rate plant).

use super::{Ctx, Failure};

/// Prints one table row per reading of the claim.
pub fn exec(ctx: &mut Ctx) -> Result<(), Failure> {
    let mut text = String::from(
        "| reading | assumption | sense before (µm) | after (µm) | ratio |\n|---|---|---|---|---|\n",
    );
    for r in paragyro_papers::claims::readings() {
        text.push_str(&format!(
            "| {} | {} | {:.4} | {:.4} | {:.3} |\n",
            r.name, r.description, r.sense_amp_before, r.sense_amp_after, r.ratio
        ));
    }
    ctx.say(&text)
}
