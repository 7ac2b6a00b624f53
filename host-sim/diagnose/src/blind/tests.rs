//! The scoring of the blind benchmark on hand-made records: the median, the confusion
//! matrix, what is right for each category, and the summary's shares.

use super::*;

fn rec(category: Category, truth: &[Effect], verdict: Answer, above: bool) -> Scored {
    Scored {
        id: "rec".into(),
        category,
        truth: truth.to_vec(),
        outside: None,
        sizes: truth.iter().map(|_| 1.0).collect(),
        verdict,
        secondary: None,
        correct: correct_for(category, truth, verdict),
        above_limit: above,
        size_over_limit: if above { 2.0 } else { 0.5 },
        oe_closure: Some(0.9),
        oracle_closure: Some(1.0),
        fitted_size: None,
        parameters_covered: (category == Category::None).then_some((7, 10)),
        seconds: 1.0,
    }
}

#[test]
fn median_of_odd_even_and_non_finite() {
    assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
    // upper middle for an even count
    assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), Some(3.0));
    assert_eq!(median(vec![f64::NAN, 5.0, f64::INFINITY]), Some(5.0));
    assert_eq!(median(Vec::new()), None);
}

#[test]
fn what_is_right_for_each_category() {
    use Effect::*;
    assert!(correct_for(Category::None, &[], Answer::None));
    assert!(!correct_for(Category::None, &[], Answer::Unknown));
    assert!(correct_for(
        Category::Outside,
        &[QuadraticStiffness],
        Answer::Unknown
    ));
    assert!(!correct_for(
        Category::Outside,
        &[QuadraticStiffness],
        Answer::None
    ));
    assert!(!correct_for(
        Category::Outside,
        &[QuadraticStiffness],
        Answer::Effect(ElectrostaticSoftening)
    ));
    assert!(correct_for(
        Category::Single,
        &[Feedthrough],
        Answer::Effect(Feedthrough)
    ));
    assert!(!correct_for(
        Category::Single,
        &[Feedthrough],
        Answer::Effect(ForceLeak)
    ));
    assert!(!correct_for(Category::Single, &[Feedthrough], Answer::None));
    // two effects: either one named is right
    assert!(correct_for(
        Category::Double,
        &[Feedthrough, ForceLeak],
        Answer::Effect(ForceLeak)
    ));
}

#[test]
fn confusion_counts_truth_against_verdict() {
    use Effect::*;
    let s = vec![
        rec(Category::None, &[], Answer::None, false),
        rec(Category::None, &[], Answer::Unknown, false),
        rec(
            Category::Single,
            &[Feedthrough],
            Answer::Effect(Feedthrough),
            true,
        ),
        rec(
            Category::Single,
            &[Feedthrough],
            Answer::Effect(Feedthrough),
            true,
        ),
        rec(
            Category::Outside,
            &[QuadraticStiffness],
            Answer::Unknown,
            true,
        ),
        rec(
            Category::Double,
            &[Feedthrough, ForceLeak],
            Answer::None,
            true,
        ),
    ];
    let c = confusion(&s);
    assert_eq!(c["none"]["none"], 1);
    assert_eq!(c["none"]["unknown"], 1);
    assert_eq!(c["feedthrough"]["feedthrough"], 2);
    assert_eq!(c["outside:quadratic_stiffness"]["unknown"], 1);
    assert_eq!(c["two effects"]["none"], 1);
    assert_eq!(
        c.values().map(|v| v.values().sum::<usize>()).sum::<usize>(),
        6
    );
}

#[test]
fn summary_shares() {
    use Effect::*;
    let s = vec![
        rec(Category::None, &[], Answer::None, false),
        rec(Category::None, &[], Answer::Unknown, false),
        rec(
            Category::Single,
            &[Feedthrough],
            Answer::Effect(Feedthrough),
            true,
        ),
        rec(Category::Single, &[ForceLeak], Answer::None, true),
        rec(Category::Single, &[ForceLeak], Answer::None, false),
        rec(
            Category::Outside,
            &[QuadraticStiffness],
            Answer::Unknown,
            true,
        ),
    ];
    let sm = summarize(&s, 6, 1);
    assert_eq!(sm.false_alarms_on_clean, Some(0.5));
    assert_eq!(sm.single_above_limit_records, 2);
    assert_eq!(sm.top1_single_above_limit, Some(0.5));
    assert_eq!(sm.top1_single_all_sizes, Some(1.0 / 3.0));
    assert_eq!(sm.unknown_on_outside, Some(1.0));
    assert_eq!(sm.parameter_coverage_1sigma, Some(0.7));
    assert_eq!(sm.parameter_coverage_samples, 20);
    // closure 0.9 against the oracle's 1.0
    assert!((sm.median_closure_over_oracle.unwrap() - 0.9).abs() < 1e-12);
    assert_eq!(sm.double_one_named, None);
}

/// An out-of-library record of a hook type.
fn out(kind: Outside, verdict: Answer, above: bool) -> Scored {
    Scored {
        outside: Some(kind),
        sizes: vec![1.0],
        ..rec(Category::Outside, &[], verdict, above)
    }
}

#[test]
fn outside_types_are_scored_by_span_and_limit() {
    use Outside::*;
    let s = vec![
        out(CoulombFriction, Answer::Unknown, true),
        out(SpuriousMode, Answer::None, true),
        out(ChargingDrift, Answer::Effect(Effect::ThermalDrift), false),
        out(PickoffLag, Answer::Effect(Effect::Anisodamping), true),
        out(PickoffLag, Answer::Unknown, true),
    ];
    assert!(s[0].correct && !s[1].correct && !s[2].correct && s[4].correct);
    let sm = summarize(&s, 5, 1);
    assert_eq!(sm.outside_records, 5);
    assert_eq!(sm.unknown_on_outside, Some(0.4));
    // the span's share leaves the pick-off lag (in span) out
    assert_eq!(sm.outside_span_records, 3);
    assert_eq!(sm.unknown_on_outside_span, Some(1.0 / 3.0));
    assert_eq!(sm.outside_span_above_limit_records, 2);
    assert_eq!(sm.unknown_on_outside_span_above_limit, Some(0.5));
    assert_eq!(sm.false_attribution_on_outside, Some(0.4));
    let c = confusion(&s);
    assert_eq!(c["outside:pickoff_lag"]["anisodamping"], 1);
    assert_eq!(c["outside:charging_drift"]["thermal_drift"], 1);
    assert_eq!(sm.outside_limits.len(), Outside::ALL.len());
    let md = markdown(&sm, &s);
    assert!(
        md.contains("| rec | outside | coulomb_friction (1.000e0) | unknown |"),
        "{md}"
    );
    assert!(
        md.contains("outside the diagnosis's span (3) | 33 %"),
        "{md}"
    );
}

#[test]
fn draws_hold_every_outside_type_through_the_hook_only() {
    let d = draw(400, 11);
    let sc = Scenario::load("characterise").unwrap();
    let outs: Vec<&Draw> = d
        .iter()
        .filter(|r| r.category == Category::Outside)
        .collect();
    // 25 % of the draw, every type, each record's effect in `outside` (not in `effects`)
    assert!(outs.len() > 70 && outs.len() < 130, "{}", outs.len());
    for kind in Outside::ALL {
        let k: Vec<&&Draw> = outs
            .iter()
            .filter(|r| r.outside.is_some_and(|o| o.kind == kind))
            .collect();
        assert!(k.len() >= 10, "{kind}: {}", k.len());
        let r = kind.size_range();
        for x in &k {
            let o = x.outside.unwrap();
            assert!(x.effects.is_empty());
            assert!(o.size.abs() >= r.low && o.size.abs() <= r.high, "{o:?}");
            let h = x.hook(&sc).unwrap();
            assert_eq!((h.name, h.p[0]), (kind.name(), o.size));
            assert!(x.size_over_limit() == o.size.abs() / r.limit);
        }
        // both sides of the detection limit are drawn
        assert!(k.iter().any(|x| x.size_over_limit() >= 1.0));
        assert!(k.iter().any(|x| x.size_over_limit() < 1.0));
    }
    assert!(
        d.iter()
            .all(|r| (r.category == Category::Outside) == r.outside.is_some())
    );
    // labels.json round-trips the out-of-library spec
    let j = serde_json::to_string(&Labels {
        seed: 11,
        records: d.clone(),
    })
    .unwrap();
    let back: Labels = serde_json::from_str(&j).unwrap();
    assert_eq!(back.records.len(), d.len());
    for (a, b) in back.records.iter().zip(&d) {
        assert_eq!(a.outside.map(|o| o.kind), b.outside.map(|o| o.kind));
        let (x, y) = (
            a.outside.map_or(0.0, |o| o.size),
            b.outside.map_or(0.0, |o| o.size),
        );
        assert!((x - y).abs() <= 1e-15 * y.abs(), "{x} {y}");
    }
}
