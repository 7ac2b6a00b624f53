//! The campaign at a small size (CI): no panic, no non-finite output, the estimate held
//! on every flagged sample, and every class that should be flagged flagged.

use super::*;

#[test]
fn plan_is_seeded_inside_its_slots_and_in_range() {
    let sched = Schedule {
        ticks: 100_000,
        warmup: 5000,
        slot: 5000,
    };
    for class in FaultClass::ALL {
        let a = plan(class, &sched, 7);
        assert_eq!(
            a,
            plan(class, &sched, 7),
            "{}: not reproducible",
            class.name()
        );
        assert_ne!(a, plan(class, &sched, 8), "{}: seed ignored", class.name());
        assert_eq!(a.len(), 19);
        for (i, e) in a.iter().enumerate() {
            let slot0 = sched.warmup + i as u64 * sched.slot;
            assert!(e.start >= slot0 && e.start <= slot0 + sched.slot / 5);
            assert!(e.len >= 1 && e.end() <= slot0 + sched.slot);
        }
        assert_eq!(FaultClass::from_name(class.name()), Some(class));
    }
    assert!(FaultClass::ALL.len() >= 12);
}

#[test]
fn quantile_is_nearest_rank() {
    let mut v = vec![5.0, 1.0, 3.0, 2.0, 4.0];
    assert_eq!(quantile(&mut v, 0.5), Some(3.0));
    assert_eq!(quantile(&mut v, 0.95), Some(5.0));
    assert_eq!(quantile(&mut [], 0.5), None);
}

#[test]
fn small_campaign_no_panic_no_non_finite_flags_raised() {
    let opts = CampaignOptions {
        ticks: 9_000,
        seed: 3,
        warmup: 3000,
        slot: 3000,
        classes: FaultClass::ALL.to_vec(),
    };
    let rep = run_campaign(&opts, &|_, _| {}).unwrap();
    assert_eq!(rep.classes.len(), FaultClass::ALL.len());
    for c in &rep.classes {
        assert_eq!(c.episodes, 2, "{}", c.class);
        assert_eq!(c.panics, 0, "{}: panics", c.class);
        assert_eq!(c.non_finite_outputs, 0, "{}: non-finite outputs", c.class);
        assert_eq!(c.held_violations, 0, "{}: estimate not held", c.class);
        if c.flag_expected {
            assert!(c.flagged > 0.0, "{}: never flagged", c.class);
        }
    }
    // the value faults reach the input check: the core counted bad samples
    for name in [
        "nan",
        "inf",
        "saturation",
        "stuck",
        "spi_crc",
        "drdy_missing",
        "accel_lost",
    ] {
        let c = rep.classes.iter().find(|c| c.class == name).unwrap();
        assert!(c.bad_samples > 0, "{name}: no bad sample counted");
        assert_eq!(c.flagged, 1.0, "{name}: an episode went unflagged");
    }
}
