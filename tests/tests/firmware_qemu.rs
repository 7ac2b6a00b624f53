//! The firmware in QEMU against the host (firmware/README.md).
//!
//! * `replay_table_regenerates`: the checked-in replay table is what `paragyro-fw-replay
//!   table` makes from `host-sim/scenarios/fw-drift-retune.toml` today (same generator
//!   code, from `paragyro-fw-replay`), and the firmware's reader gets the scenario's core
//!   configuration back from it.
//! * `qemu_matches_host`: builds the `qemu` board with `tick-stream` and `capture` (its own
//!   target directory, `target/fw-test`), runs it in QEMU (`firmware/scripts/qemu-run.sh`: exit 0
//!   only if the run converged and retuned), and compares every tick's outputs with the
//!   host running (a) the same firmware library over the same replay devices and (b) the
//!   bare `paragyro_core::Estimator<f32>` on the frames decoded on the host: **bit for
//!   bit**. The capture lines are turned into a record by the capture converter and checked
//!   against the inputs the core was given and against the simulated record.
//!
//! Set `PARAGYRO_SKIP_QEMU=1` to skip the QEMU test (e.g. on a machine without
//! qemu-system-arm or defmt-print); CI installs both and runs it.

use std::path::{Path, PathBuf};
use std::process::Command;

use embedded_hal::delay::DelayNs;
use paragyro_core::{Cplx, Estimator, Lockin, Sample};
use paragyro_firmware::drivers::ad9959::DEFAULT_SYSCLK_HZ;
use paragyro_firmware::drivers::ads131m08::RawCode;
use paragyro_firmware::replay::DdsCapture;
use paragyro_firmware::run::{ReplayCheck, apply_controls, calibration, replay_app};
use paragyro_firmware::table::ReplayTable;
use paragyro_simulator::scenario::Scenario;

use paragyro_fw_replay::capture;
use paragyro_fw_replay::table as fwtable;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

fn table_bytes() -> Vec<u8> {
    std::fs::read(root().join("firmware/replay/fw-drift-retune.bin")).expect("replay table")
}

struct NoWait;
impl DelayNs for NoWait {
    fn delay_ns(&mut self, _ns: u32) {}
}

#[test]
fn replay_table_regenerates() {
    let sc = Scenario::load(
        root()
            .join("host-sim/scenarios/fw-drift-retune.toml")
            .to_str()
            .unwrap(),
    )
    .expect("scenario");
    let t = fwtable::build(&sc, None).expect("build");
    let file = table_bytes();
    assert_eq!(
        t.bytes.len(),
        file.len(),
        "firmware/replay/fw-drift-retune.bin is stale: regenerate it with \
         `cargo run --release -p paragyro-fw-replay -- table`"
    );
    if let Some(i) = t.bytes.iter().zip(&file).position(|(a, b)| a != b) {
        panic!(
            "firmware/replay/fw-drift-retune.bin differs from the generator's output at byte {i} \
             (header is 1024 bytes, samples 60 bytes each): regenerate it with \
             `cargo run --release -p paragyro-fw-replay -- table`"
        );
    }
    let table = ReplayTable::parse(&file).expect("parse");
    assert_eq!(
        table.config(),
        t.config,
        "the firmware reads another config"
    );
    assert_eq!(table.len(), t.record.rows.len());
    assert!(table.len() >= 5000, "at least 10 s at 500 Hz");
    assert_eq!(table.controls(), 1, "the dither-off event at 6 s");
    let c = table.control(0).unwrap();
    assert_eq!((c.tick, c.kind, c.value), (2999, 1, 0.0));
}

/// One `TICK` line of the firmware.
#[derive(Debug, PartialEq)]
struct TickLine {
    k: usize,
    cmd: f64,
    pump: f64,
    scale: f64,
    health: u32,
    events: u8,
    faults: u8,
    digest: u64,
    theta: Vec<f64>,
}

fn field<'a>(line: &'a str, key: &str) -> &'a str {
    let pat = format!(" {key}=");
    let start = line
        .find(&pat)
        .unwrap_or_else(|| panic!("no {key}= in {line}"))
        + pat.len();
    let rest = &line[start..];
    if rest.starts_with('[') {
        &rest[..=rest.find(']').unwrap()]
    } else {
        rest.split_whitespace().next().unwrap()
    }
}

fn floats(s: &str) -> Vec<f64> {
    s.trim_matches(|c| c == '[' || c == ']')
        .split(',')
        .map(|x| x.trim().parse::<f64>().unwrap())
        .collect()
}

fn parse_tick(line: &str) -> TickLine {
    let mut theta = floats(field(line, "t1"));
    theta.extend(floats(field(line, "t2")));
    TickLine {
        k: field(line, "k").parse().unwrap(),
        cmd: field(line, "cmd").parse().unwrap(),
        pump: field(line, "pump").parse().unwrap(),
        scale: field(line, "scale").parse().unwrap(),
        health: field(line, "h").parse().unwrap(),
        events: field(line, "ev").parse().unwrap(),
        faults: field(line, "f").parse().unwrap(),
        digest: u64::from_str_radix(field(line, "d"), 16).unwrap(),
        theta,
    }
}

/// The host's run of the same library code: one `TickLine` per tick and the final digest.
fn host_run(table: &ReplayTable<'_>) -> (Vec<TickLine>, u64, bool) {
    let dds = DdsCapture::new(DEFAULT_SYSCLK_HZ);
    let mut io = dds.io_update();
    let mut app = replay_app(*table, &dds, &mut io, &mut NoWait).expect("setup");
    let mut check = ReplayCheck::new(table);
    let mut out = Vec::new();
    for k in 0..table.len() {
        apply_controls(table, k, &mut app);
        let (p, s) = table.pump(k).unwrap();
        let r = app.tick_with_pump(&mut io, p, s);
        check.observe(table, k, &app, &r, dds.active_pump_hz());
        let (t1, t2) = app.estimator().theta();
        out.push(TickLine {
            k,
            cmd: r.out.pump_hz_next,
            pump: r.pump_hz,
            scale: r.out.pump_scale_next,
            health: r.out.health.bits(),
            events: r.out.events,
            faults: r.faults,
            digest: check.digest(),
            theta: t1.iter().chain(t2.iter()).copied().collect(),
        });
    }
    let v = check.verdict(table, &app, dds.active_pump_hz());
    (out, v.digest, v.pass())
}

/// The bare core on the host, on the frames decoded here (codes × calibration), with the
/// table's pump and control events: per tick (command, θ̂).
fn bare_core(table: &ReplayTable<'_>) -> Vec<(f64, Vec<f64>)> {
    let cfg = table.config();
    let mut est: Estimator<f32> = cfg.build().expect("config");
    let cal = [
        calibration(table.um_per_volt_x()),
        calibration(table.um_per_volt_y()),
    ];
    let lsb = paragyro_firmware::drivers::adxl355::Range::G8.mps2_per_lsb();
    let mut out = Vec::new();
    for k in 0..table.len() {
        for i in 0..table.controls() {
            let c = table.control(i).unwrap();
            if c.tick as usize == k {
                assert_eq!(c.kind, 1, "only the dither event is expected");
                est.set_dither(c.value != 0.0);
            }
        }
        let s = table.sample(k).unwrap();
        let um = |axis: usize, codes: [i32; 7]| {
            let u = cal[axis].to_um(&codes.map(RawCode::saturating_new));
            let [r1, r2, r3] = u.re_um;
            let [i1, i2, i3] = u.im_um;
            (
                u.x0_um,
                [Cplx::new(r1, i1), Cplx::new(r2, i2), Cplx::new(r3, i3)],
            )
        };
        let (x0, x) = um(0, s.adc_x);
        let (y0, y) = um(1, s.adc_y);
        let sample = Sample {
            lockin: Lockin {
                x0_um: x0,
                x_um: x,
                y0_um: y0,
                y_um: y,
            },
            accel_mps2: [s.accel[0] as f32 * lsb, s.accel[1] as f32 * lsb],
            pump_hz: s.pump_hz,
            pump_scale: s.pump_scale,
            temp_c: None,
        };
        let o = est.step(&sample);
        let (t1, t2) = est.theta();
        out.push((
            o.pump_hz_next,
            t1.iter().chain(t2.iter()).copied().collect(),
        ));
    }
    out
}

#[test]
fn host_library_equals_bare_core() {
    let bytes = table_bytes();
    let table = ReplayTable::parse(&bytes).expect("parse");
    let (lib, _, pass) = host_run(&table);
    assert!(pass, "the replay run fails its verdict on the host");
    let bare = bare_core(&table);
    for (a, (cmd, theta)) in lib.iter().zip(&bare) {
        assert_eq!(a.cmd.to_bits(), cmd.to_bits(), "tick {}: command", a.k);
        assert_eq!(&a.theta, theta, "tick {}: θ̂", a.k);
    }
}

#[test]
fn qemu_matches_host() {
    if std::env::var("PARAGYRO_SKIP_QEMU").as_deref() == Ok("1") {
        eprintln!("PARAGYRO_SKIP_QEMU=1: the QEMU comparison is skipped");
        return;
    }
    let root = root();
    let target_dir = std::env::var("PARAGYRO_FW_TEST_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("target/fw-test"));
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .env("CARGO_TARGET_DIR", &target_dir)
        .args([
            "build",
            "-p",
            "paragyro-firmware",
            "--target",
            "thumbv7em-none-eabihf",
            "--release",
            "--features",
            "tick-stream,capture",
        ])
        .status()
        .expect("cargo build of the firmware");
    assert!(status.success(), "firmware build failed");
    let elf = target_dir.join("thumbv7em-none-eabihf/release/paragyro-firmware");
    let out = Command::new(root.join("firmware/scripts/qemu-run.sh"))
        .arg(&elf)
        .output()
        .expect(
            "firmware/scripts/qemu-run.sh (needs qemu-system-arm and defmt-print; \
             PARAGYRO_SKIP_QEMU=1 skips this test)",
        );
    let text = String::from_utf8_lossy(&out.stdout);
    let tail: Vec<&str> = text
        .lines()
        .filter(|l| !l.contains(" TICK ") && !l.contains(" CAP "))
        .rev()
        .take(12)
        .collect();
    assert!(
        out.status.success(),
        "QEMU run failed ({}):\n{}\n{}",
        out.status,
        tail.into_iter().rev().collect::<Vec<_>>().join("\n"),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("PASS"));

    let bytes = table_bytes();
    let table = ReplayTable::parse(&bytes).expect("parse");
    let fw: Vec<TickLine> = text
        .lines()
        .filter(|l| l.contains(" TICK k="))
        .map(parse_tick)
        .collect();
    assert_eq!(fw.len(), table.len(), "one TICK line per sample");
    let (host, host_digest, pass) = host_run(&table);
    assert!(pass);
    let mut first_diff = None;
    let mut max_theta_rel: f64 = 0.0;
    let mut max_cmd: f64 = 0.0;
    for (a, b) in fw.iter().zip(&host) {
        if a != b && first_diff.is_none() {
            first_diff = Some(a.k);
        }
        max_cmd = max_cmd.max((a.cmd - b.cmd).abs());
        for (x, y) in a.theta.iter().zip(&b.theta) {
            max_theta_rel = max_theta_rel.max(((x - y) / y.abs().max(1e-30)).abs());
        }
    }
    assert!(
        first_diff.is_none(),
        "QEMU and host differ from tick {:?} on: max |Δcmd| {max_cmd} Hz, max |Δθ/θ| {max_theta_rel}",
        first_diff
    );
    let fw_digest = fw.last().unwrap().digest;
    assert_eq!(fw_digest, host_digest, "digest");
    assert!(
        text.contains(&format!("output digest {host_digest:016x}")),
        "final digest line"
    );
    println!(
        "QEMU = host, bit for bit, over {} ticks (digest {host_digest:016x})",
        fw.len()
    );

    // the capture: the record the converter makes is the core's input, exactly
    let rec = capture::parse_capture(&text, "qemu").expect("capture log");
    assert!(rec.warnings.is_empty(), "{:?}", rec.warnings);
    assert_eq!(rec.rows.len(), table.len());
    let cfg = table.config();
    assert_eq!(rec.header.f0_hz, cfg.f0_hz);
    assert_eq!(rec.header.fs_hz, cfg.fs_hz);
    let sim = fwtable::build(
        &Scenario::load(
            root.join("host-sim/scenarios/fw-drift-retune.toml")
                .to_str()
                .unwrap(),
        )
        .unwrap(),
        None,
    )
    .unwrap()
    .record;
    let upc = |axis: usize| {
        let c = calibration(if axis == 0 {
            table.um_per_volt_x()
        } else {
            table.um_per_volt_y()
        });
        f64::from(c.um_per_code[0])
    };
    let (qx, qy) = (upc(0), upc(1));
    for (k, (r, s)) in rec.rows.iter().zip(&sim.rows).enumerate() {
        let ts = table.sample(k).unwrap();
        let (lr, ls) = (&r.lockin, &s.lockin);
        // the pump and the accelerations are the table's, exactly
        assert_eq!(r.pump_hz.to_bits(), ts.pump_hz.to_bits(), "row {k}: pump");
        let back = r.to_sample::<f32>(&rec.header);
        assert_eq!(back.pump_scale, ts.pump_scale, "row {k}: pump scale");
        // the lock-in values are the simulator's to within half an ADC code (+ f32)
        let xs = [
            (lr.x0_um, ls.x0_um, qx),
            (lr.x_um[0].re, ls.x_um[0].re, qx),
            (lr.x_um[0].im, ls.x_um[0].im, qx),
            (lr.y0_um, ls.y0_um, qy),
            (lr.y_um[0].re, ls.y_um[0].re, qy),
            (lr.y_um[0].im, ls.y_um[0].im, qy),
        ];
        for (cap, simv, q) in xs {
            assert!(
                (cap - simv).abs() <= 0.5 * q + 1e-6 * simv.abs(),
                "row {k}: captured {cap} vs simulated {simv} (code {q})"
            );
        }
    }
    // replaying the captured record with the bare core gives the firmware's outputs
    let mut est: Estimator<f32> = cfg.build().unwrap();
    for (k, r) in rec.rows.iter().enumerate() {
        if k == 2999 {
            est.set_dither(false);
        }
        let o = est.step(&r.to_sample::<f32>(&rec.header));
        assert_eq!(
            o.pump_hz_next.to_bits(),
            fw[k].cmd.to_bits(),
            "tick {k}: the core on the captured record"
        );
    }
    println!("capture → record → core = firmware, bit for bit");
}
