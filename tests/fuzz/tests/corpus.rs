//! The fuzz harnesses as a plain, bounded test: every target over its seed corpus and a
//! fixed number of seeded mutations of it (bit flips, byte sets, cuts, insertions, splices
//! of awkward tokens). Runs on stable without libFuzzer or a C++ compiler (CI runs the
//! libFuzzer targets themselves: `cargo xtask fuzz`); a crash found by libFuzzer goes into
//! `regressions/<target>/` and is replayed here too.
//!
//! The seeds are also libFuzzer's committed seeds (`seeds/<target>/`; `corpus/` is cargo-fuzz's own, ignored), written by
//! `cargo test --release --manifest-path tests/fuzz/Cargo.toml -- --ignored write_seed_corpus`;
//! the test `seed_corpus_is_committed` checks the files match.

use paragyro_firmware::drivers::ads131m08::{FRAME_BYTES, Frame};

/// xorshift64*: the mutations are the same on every run.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

const TOKENS: [&[u8]; 14] = [
    b"nan",
    b"inf",
    b"-inf",
    b"1e309",
    b"-0",
    b"0",
    b"1e-320",
    b"\"",
    b"[",
    b"]]",
    b"\n",
    b",",
    b"=",
    b"# format: paragyro-record 1\n",
];

/// One seeded mutation of `seed`.
fn mutate(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(v.len() + 1);
        match rng.below(6) {
            0 if !v.is_empty() => {
                let i = at.min(v.len() - 1);
                v[i] ^= 1 << rng.below(8);
            }
            1 if !v.is_empty() => {
                let i = at.min(v.len() - 1);
                v[i] = rng.next() as u8;
            }
            2 => {
                let end = (at + rng.below(16)).min(v.len());
                v.drain(at.min(end)..end);
            }
            3 => {
                let t = TOKENS[rng.below(TOKENS.len())];
                v.splice(at..at, t.iter().copied());
            }
            4 => v.truncate(at),
            _ => {
                let n = rng.below(8);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
                v.splice(at..at, bytes);
            }
        }
    }
    v
}

fn run(target: fn(&[u8]), seeds: &[Vec<u8>], n: usize, seed: u64) {
    let mut rng = Rng(seed);
    for s in seeds {
        target(s);
    }
    for i in 0..n {
        let s = &seeds[i % seeds.len()];
        target(&mutate(&mut rng, s));
    }
}

/// Crash inputs kept as regression cases (`regressions/<target>/*`).
fn regressions(target: &str) -> Vec<Vec<u8>> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("regressions")
        .join(target);
    let Ok(rd) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    rd.filter_map(|e| std::fs::read(e.ok()?.path()).ok())
        .collect()
}

fn record_seed() -> Vec<u8> {
    let mut t = String::from(
        "# format: paragyro-record 1\n# f0_hz: 10799.814442720044\n# l0_um: 1\n# fs_hz: 500\n\
         # lockin_lpf_order: 4\n# lockin_lpf_hz: 150\n# pump_amp_ref_v: 1\n\
         t_s,pump_hz,pump_amp_v,ax_mps2,ay_mps2,x0_um,x1_re_um,x1_im_um,x2_re_um,x2_im_um,\
         x3_re_um,x3_im_um,y0_um,y1_re_um,y1_im_um,y2_re_um,y2_im_um,y3_re_um,y3_im_um\n",
    );
    for k in 0..20 {
        let d = (k % 7) as f64 * 1e-5;
        t.push_str(&format!(
            "{},21883.9526,1,98.0665,98.0665,{},1.2,-1.27,1e-4,{},0.001,0.002,0.0207,0.9,1.2,{},1e-4,0.0005,-0.001\n",
            k as f64 * 0.002,
            0.0204 + d,
            d,
            d
        ));
    }
    t.into_bytes()
}

/// Seeds of the targets with generated seeds (the scenario parser's are the committed
/// scenarios of `host-sim/scenarios/`).
fn seeds(target: &str) -> Vec<Vec<u8>> {
    match target {
        "record_reader" => vec![record_seed()],
        "ads131m08_frame" => frame_seeds(),
        "estimator_step" => step_seeds(),
        "diagnosis" => diagnosis_seeds(),
        _ => Vec::new(),
    }
}

const SEEDED: [&str; 4] = [
    "record_reader",
    "ads131m08_frame",
    "estimator_step",
    "diagnosis",
];

fn corpus_dir(target: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("seeds")
        .join(target)
}

#[test]
#[ignore = "writes the committed seed corpus (run by hand after changing a seed)"]
fn write_seed_corpus() {
    for t in SEEDED {
        let dir = corpus_dir(t);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        for (i, s) in seeds(t).iter().enumerate() {
            std::fs::write(dir.join(format!("seed-{i:02}")), s).unwrap();
        }
    }
}

#[test]
fn seed_corpus_is_committed() {
    for t in SEEDED {
        for (i, s) in seeds(t).iter().enumerate() {
            let f = corpus_dir(t).join(format!("seed-{i:02}"));
            let got = std::fs::read(&f).unwrap_or_default();
            assert!(
                &got == s,
                "{} differs from its seed: run the ignored test write_seed_corpus",
                f.display()
            );
        }
    }
}

#[test]
fn record_reader_corpus() {
    let rec = record_seed();
    assert!(
        paragyro_simulator::record::parse_record(std::str::from_utf8(&rec).unwrap(), "seed")
            .is_ok(),
        "the seed record must be valid"
    );
    let mut seeds = vec![rec];
    seeds.extend(regressions("record_reader"));
    run(paragyro_fuzz::record_reader, &seeds, 20_000, 1);
}

#[test]
fn scenario_parser_corpus() {
    let mut seeds: Vec<Vec<u8>> = [
        include_str!("../../../host-sim/scenarios/identify.toml"),
        include_str!("../../../host-sim/scenarios/drift-retune.toml"),
        include_str!("../../../host-sim/scenarios/paper-switch.toml"),
        include_str!("../../../host-sim/scenarios/paper-claim.toml"),
        include_str!("../../../host-sim/scenarios/characterise.toml"),
        include_str!("../../../host-sim/scenarios/fw-drift-retune.toml"),
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    for s in &seeds {
        assert!(
            paragyro_simulator::scenario::Scenario::from_toml_str(
                std::str::from_utf8(s).unwrap(),
                "seed"
            )
            .is_ok()
        );
    }
    seeds.extend(regressions("scenario_parser"));
    run(paragyro_fuzz::scenario_parser, &seeds, 6_000, 2);
}

fn frame_seeds() -> Vec<Vec<u8>> {
    let mut rng = Rng(3);
    let mut seeds = vec![Frame::default().encode().to_vec()];
    for _ in 0..16 {
        let mut b = [0u8; FRAME_BYTES];
        b.iter_mut().for_each(|x| *x = rng.next() as u8);
        // a valid frame carrying these codes, and the random bytes themselves
        if let Ok(f) = Frame::decode(&b) {
            seeds.push(f.encode().to_vec());
        }
        seeds.push(b.to_vec());
    }
    seeds
}

#[test]
fn ads131m08_frame_corpus() {
    let mut seeds = frame_seeds();
    seeds.extend(regressions("ads131m08_frame"));
    run(paragyro_fuzz::ads131m08_frame, &seeds, 200_000, 4);
}

fn step_seeds() -> Vec<Vec<u8>> {
    let mut rng = Rng(5);
    let mut seeds: Vec<Vec<u8>> = Vec::new();
    for _ in 0..8 {
        // a run of plausible samples, then arbitrary samples and commands
        let mut v = vec![6u8, 200];
        for _ in 0..rng.below(600) {
            v.push(rng.next() as u8);
        }
        seeds.push(v);
    }
    seeds
}

#[test]
fn estimator_step_corpus() {
    let mut seeds = step_seeds();
    seeds.extend(regressions("estimator_step"));
    run(paragyro_fuzz::estimator_step, &seeds, 400, 6);
}

/// The diagnosis's seeds: the base record as it is, and one edit of each kind
/// (`paragyro_fuzz::diagnosis`'s opcodes: scale, step, a value, a stuck channel, a reversal,
/// a temperature ramp, a cut, a spike).
fn diagnosis_seeds() -> Vec<Vec<u8>> {
    let span = |k0: u16, len: u16| {
        let mut v = k0.to_le_bytes().to_vec();
        v.extend(len.to_le_bytes());
        v
    };
    let mut seeds = vec![Vec::new()];
    for (op, col, rest) in [
        (
            0u8,
            5u8,
            [span(600, 300), 1.3f64.to_le_bytes().to_vec()].concat(),
        ),
        (
            1,
            12,
            [span(900, 2000), 2e-3f64.to_le_bytes().to_vec()].concat(),
        ),
        (
            2,
            9,
            [span(700, 40), f64::NAN.to_le_bytes().to_vec()].concat(),
        ),
        (3, 14, span(1000, 200)),
        (4, 0, [span(800, 2000), vec![100]].concat()),
        (5, 1, [span(500, 2000), vec![40]].concat()),
        (6, 0, 1100u16.to_le_bytes().to_vec()),
        (
            7,
            16,
            [
                1200u16.to_le_bytes().to_vec(),
                5.0f64.to_le_bytes().to_vec(),
            ]
            .concat(),
        ),
    ] {
        let mut v = vec![op, col];
        v.extend(rest);
        seeds.push(v);
    }
    seeds
}

/// The diagnosis over its seeds and a few mutations of them (each run is ≈ 0.2 s: libFuzzer
/// explores further in `cargo xtask fuzz`).
#[test]
fn diagnosis_corpus() {
    let mut seeds = diagnosis_seeds();
    seeds.extend(regressions("diagnosis"));
    run(paragyro_fuzz::diagnosis, &seeds, 16, 7);
}
