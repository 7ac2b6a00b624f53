//! Helpers shared by the tests that replay a simulator's record here.

use paragyro_refsim::protocol::Table;
use paragyro_simulator::record::Record;

/// A record's inputs (pump frequency, pump scale s = (V/V_ref)², accelerations) as this
/// generator's input table.
pub fn inputs_of(rec: &Record) -> Table {
    let v0 = rec.header.pump_amp_ref_v;
    Table {
        pump_hz: rec.rows.iter().map(|r| r.pump_hz).collect(),
        s: rec
            .rows
            .iter()
            .map(|r| (r.pump_amp_v / v0).powi(2))
            .collect(),
        accel: rec.rows.iter().map(|r| [r.ax_mps2, r.ay_mps2]).collect(),
    }
}
