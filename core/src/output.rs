//! What one [`crate::Estimator::step`] returns: the next pump command, the health and
//! the events of the step.

use crate::health::Health;
pub use crate::rate::RateOutput;

/// Event bits of one step ([`StepOutput::events`]).
pub mod event {
    /// The drive RLS was reset by the change detector.
    pub const CHANGE_DRIVE: u8 = 1;
    /// The sense RLS was reset by the change detector.
    pub const CHANGE_SENSE: u8 = 2;
    /// A retune ramp started.
    pub const RETUNE_START: u8 = 4;
    /// A retune ramp finished.
    pub const RETUNE_DONE: u8 = 8;
    /// A retune was aborted (drive lock lost).
    pub const RETUNE_ABORT: u8 = 16;
    /// The sample was bad and skipped.
    pub const BAD_INPUT: u8 = 32;
    /// The estimate settled (rising edge).
    pub const SETTLED: u8 = 64;
}

/// What one step returns.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepOutput {
    /// Pump frequency to command for the next sample instant, Hz.
    pub pump_hz_next: f64,
    /// Multiplier of the pump voltage scale s = (V/V0)² to command for the next sample
    /// instant (the amplitude part of the excitation; 1 when off). The pump voltage is
    /// V0·√(s_base · pump_scale_next).
    pub pump_scale_next: f64,
    /// Health after this sample.
    pub health: Health,
    /// Events of this step (see [`event`]).
    pub events: u8,
    /// The RLS was updated with this sample.
    pub updated: bool,
    /// The fast rate channel: rate, slow rate, quadrature and the rate's validity.
    pub rate: RateOutput,
}
