//! The diagnosis on this generator's records (issue 31's protocol generality): a clean
//! device whose rate table reverses reads `none`. The reversal is this generator's smooth
//! one (Ω = R·cos(π(t − t0)/T)); the diagnosis's re-simulation must take the table's rate
//! at each interval's midpoint and its angular acceleration γ′ for the ramp not to be read
//! as a gap (host-sim/diagnose/src/diagnose/resim.rs).

use paragyro_diagnose::diagnose::{Options, diagnose};
use paragyro_refsim::format::to_text;
use paragyro_refsim::generate::{Category, draw};
use paragyro_refsim::protocol::Reversal;

#[test]
fn a_clean_device_through_a_rate_table_reversal_reads_none() {
    // a drawn device and protocol (tolerances, dithers, steps, a temperature ramp), its
    // effects removed, the reversal at 4 s over 0.5 s (inside the fit span)
    let mut d = draw(1, 3101, 10.0, 1.0).remove(0);
    d.category = Category::None;
    d.effects.clear();
    d.outside = None;
    d.vib_phase_rad = 0.0;
    d.protocol.reversal = Some(Reversal {
        t_s: 4.0,
        ramp_s: 0.5,
    });
    let rate = d.protocol.rate_dps;
    let sim = d.simulate(4, 150.0, 1e-9).unwrap();
    let text = to_text(&d.header(4, 150.0), &sim.rows);
    let rec = paragyro_simulator::record::parse_record(&text, "refsim reversal").unwrap();
    let table: Vec<f64> = rec.rows.iter().filter_map(|r| r.rate_ref_dps).collect();
    assert_eq!(table.len(), rec.rows.len());
    assert!((table[0] - rate).abs() < 1e-9 && (table[table.len() - 1] + rate).abs() < 1e-9);
    let report = diagnose(&rec, &Options::default()).unwrap().report;
    assert_eq!(
        report.verdict.to_string(),
        "none",
        "rate {rate:.1} °/s: {:?}",
        report.ranking
    );
}
