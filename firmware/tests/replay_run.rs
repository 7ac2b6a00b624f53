//! The QEMU board's replay run on the host (same library code as the board): the checked-in
//! table parses, the chips initialise over it, and the run passes its verdict.
use embedded_hal_mock::eh1::delay::NoopDelay;
use paragyro_firmware::drivers::ad9959::DEFAULT_SYSCLK_HZ;
use paragyro_firmware::replay::DdsCapture;
use paragyro_firmware::run::{ReplayCheck, apply_controls, replay_app};
use paragyro_firmware::table::ReplayTable;

static TABLE: &[u8] = include_bytes!("../replay/fw-drift-retune.bin");

#[test]
fn replay_run_passes_on_the_host() {
    let table = ReplayTable::parse(TABLE).expect("table");
    let cap = DdsCapture::new(DEFAULT_SYSCLK_HZ);
    let mut io = cap.io_update();
    let mut app = replay_app(table, &cap, &mut io, &mut NoopDelay::new()).expect("setup");
    let mut check = ReplayCheck::new(&table);
    for k in 0..table.len() {
        apply_controls(&table, k, &mut app);
        let (p, s) = table.pump(k).unwrap();
        let r = app.tick_with_pump(&mut io, p, s);
        check.observe(&table, k, &app, &r, cap.active_pump_hz());
    }
    let v = check.verdict(&table, &app, cap.active_pump_hz());
    println!("{v:#?}\ndigest {:016x}", v.digest);
    println!(
        "fw counters {:?}\ncore counters {:?}",
        app.counters(),
        app.estimator().counters()
    );
    assert!(v.pass(), "{v:?}");
}
