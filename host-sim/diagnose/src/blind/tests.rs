//! The scoring of the blind benchmark on hand-made records: the median, the confusion
//! matrix, what is right for each category, and the summary's shares.

use super::*;

fn rec(category: Category, truth: &[Effect], verdict: Answer, above: bool) -> Scored {
    Scored {
        id: "rec".into(),
        category,
        truth: truth.to_vec(),
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
