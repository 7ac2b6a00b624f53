//! The firmware's budgets, checked in CI (`paragyro-fil budget`, .ci/run; the tick guard
//! also in tests/tests/fil.rs).
//!
//! * flash of the stm32f405 image ≤ [`FLASH_BUDGET`];
//! * its static RAM plus the stack's high-water mark measured in the loop (the `fil`
//!   board runs the same `App` and tick; the stm32f405 board itself has never run) ≤
//!   [`RAM_BUDGET`] (an STM32G431-class part);
//! * instructions per tick on the real-board path (the `fil` board, the fake chips
//!   excluded, exact): mean ≤ [`TICK_MEAN_TARGET`], costliest tick ≤ [`TICK_MAX_TARGET`]
//!   (issue 12's targets, enforced as they are: QEMU's counts are exact, so there is no
//!   noise to leave room for).

use serde::Serialize;

use crate::Summary;

/// Flash budget of the stm32f405 image (the warm start included), bytes: 128 KiB, an
/// STM32G431xB-class part (firmware/README.md "Budgets").
pub const FLASH_BUDGET: u64 = 128 * 1024;
/// Static RAM plus the stack peak, bytes.
pub const RAM_BUDGET: u64 = 32 * 1024;
/// The mean instructions per tick on `drift-retune` in the loop (the current figure: the
/// front page's headline table; `cargo fw-loop`, `summary.json` `instr_mean`).
pub const TICK_MEAN_TARGET: f64 = 12_000.0;
/// The costliest tick (`summary.json` `instr_max`; the current figure: the front page's
/// headline table).
pub const TICK_MAX_TARGET: u64 = 15_000;

/// The budgets against an image and a loop summary.
#[derive(Clone, Debug, Serialize)]
pub struct Budgets {
    /// Flash of the stm32f405 image, bytes.
    pub flash: u64,
    /// Its static RAM, bytes.
    pub ram_static: u64,
    /// The stack peak measured in the loop, bytes.
    pub stack_peak: u64,
    /// Mean exact instructions per tick.
    pub instr_mean: f64,
    /// Costliest tick.
    pub instr_max: u64,
    /// What failed (empty: all within budget or guard).
    pub failures: Vec<String>,
}

/// Checks the stm32f405 image `elf` and the loop's `summary`.
pub fn check(elf: &[u8], summary: &Summary) -> anyhow::Result<Budgets> {
    let (flash, ram_static) = crate::elf::flash_and_ram(elf)?;
    let stack_peak = u64::from(summary.stack_peak_bytes);
    let mut failures = Vec::new();
    failures.extend(flash_guard(flash));
    if stack_peak == 0 {
        failures.push("no stack peak in the summary".into());
    }
    if ram_static + stack_peak > RAM_BUDGET {
        failures.push(format!(
            "static RAM {ram_static} B + stack peak {stack_peak} B > {RAM_BUDGET} B"
        ));
    }
    failures.extend(tick_guard(summary.instr_mean, summary.instr_max));
    Ok(Budgets {
        flash,
        ram_static,
        stack_peak,
        instr_mean: summary.instr_mean,
        instr_max: summary.instr_max,
        failures,
    })
}

/// The flash budget: what exceeds it (`None`: within).
pub fn flash_guard(flash: u64) -> Option<String> {
    (flash > FLASH_BUDGET).then(|| format!("flash {flash} B > {FLASH_BUDGET} B"))
}

/// The tick's budget: what exceeds it (empty: within).
pub fn tick_guard(mean: f64, max: u64) -> Vec<String> {
    let mut f = Vec::new();
    if mean.is_nan() || mean > TICK_MEAN_TARGET {
        f.push(format!("tick mean {mean:.0} > {TICK_MEAN_TARGET}"));
    }
    if max > TICK_MAX_TARGET {
        f.push(format!("tick max {max} > {TICK_MAX_TARGET}"));
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_flash_guard_takes_the_warm_start_image_and_flags_128_kib_plus_one() {
        assert_eq!(FLASH_BUDGET, 131_072);
        // an stm32f405 image with the warm start, over 64 KiB, is within the budget
        assert!(flash_guard(74_428).is_none());
        assert!(flash_guard(65_537).is_none());
        assert!(flash_guard(131_072).is_none());
        assert!(flash_guard(131_073).is_some());
        // the RAM budget is unchanged
        assert_eq!(RAM_BUDGET, 32_768);
    }

    #[test]
    fn the_tick_guard_flags_a_regression_and_nan() {
        assert!(tick_guard(11_610.0, 14_358).is_empty());
        assert!(tick_guard(12_000.0, 15_000).is_empty());
        assert_eq!(tick_guard(12_001.0, 14_999).len(), 1);
        assert_eq!(tick_guard(11_000.0, 15_001).len(), 1);
        // both over: each guard flags its own
        assert_eq!(tick_guard(14_675.0, 17_540).len(), 2);
        assert_eq!(tick_guard(f64::NAN, 0).len(), 1);
    }
}
