//! Stage 3, fit and rank: the baseline, the catch-all, the floor (the best held-out energy
//! any model reaches), each testable library effect fitted once with the rate, scored on
//! the held-out span, its residual checked by the catch-all, and the pairs this record
//! cannot tell apart.

use paragyro_simulator::effects::{Effect, LIBRARY, Signature};

use super::columns::Columns;
use super::locate::nan_low;
use super::lsq::{Bank, Fit, corr_length};
use super::report::Candidate;
use super::rows::{Rows, Spans};
use super::{COHERENT, GAP_MIN, NR, T_SIG};

/// The fits every later stage uses.
pub(crate) struct Fits {
    pub bank: Bank,
    /// The baseline (the rate, or nothing).
    pub base_fit: Fit,
    /// The catch-all.
    pub ca_fit: Fit,
    /// The catch-all and every library column.
    pub floor_fit: Fit,
    /// Each testable library effect with the baseline, in library order.
    pub cand_fits: Vec<(Effect, Vec<usize>, Fit)>,
    /// Held-out baseline energy E0.
    pub e0: f64,
    /// The floor: the lowest held-out energy of any model.
    pub e_floor: f64,
    /// E0 − E_floor (≥ 0).
    pub explainable: f64,
}

impl Fits {
    pub(crate) fn build(cols: &Columns, rows: &Rows, spans: &Spans) -> Self {
        Self::build_on(cols, rows, spans, &rows.usable)
    }

    /// [`Fits::build`] on the samples `usable` marks (the rows' own, or fewer).
    pub(crate) fn build_on(cols: &Columns, rows: &Rows, spans: &Spans, usable: &[bool]) -> Self {
        let refs: Vec<&[[f64; NR]]> = cols.cols.iter().map(|c| c.v.as_slice()).collect();
        let bank = Bank::build(
            &refs,
            &rows.y,
            usable,
            &spans.fit_blocks,
            spans.hold.clone(),
        );
        let base_fit = bank.fit(&cols.base_cols);
        let e0 = base_fit.e_hold;
        let tested: Vec<Effect> = LIBRARY
            .into_iter()
            .filter(|&e| !cols.of(e).is_empty())
            .collect();
        let all_lib: Vec<usize> = tested.iter().flat_map(|&e| cols.of(e)).collect();
        use rayon::prelude::*;
        let everything: Vec<usize> = cols.ca_idx.iter().chain(&all_lib).copied().collect();
        // the fits are independent: each on its own thread
        let ((ca_fit, floor_fit), cand_fits) = rayon::join(
            || {
                rayon::join(
                    || bank.fit(&cols.with(&cols.ca_idx)),
                    || bank.fit(&cols.with(&everything)),
                )
            },
            || -> Vec<(Effect, Vec<usize>, Fit)> {
                tested
                    .par_iter()
                    .map(|&e| {
                        let ci = cols.of(e);
                        let f = bank.fit(&cols.with(&ci));
                        (e, ci, f)
                    })
                    .collect()
            },
        );
        // the floor: the best held-out energy any model reaches (the everything-model can
        // generalise worse than a single candidate to the held-out operating point)
        let e_floor = cand_fits
            .iter()
            .map(|c| c.2.e_hold)
            .fold(floor_fit.e_hold.min(e0).min(ca_fit.e_hold), f64::min);
        Fits {
            bank,
            base_fit,
            ca_fit,
            floor_fit,
            cand_fits,
            e0,
            e_floor,
            explainable: (e0 - e_floor).max(0.0),
        }
    }

    /// The fit of a library effect (with the baseline), if it was tested.
    pub(crate) fn of(&self, effect: Effect) -> Option<&Fit> {
        self.cand_fits.iter().find(|c| c.0 == effect).map(|c| &c.2)
    }

    /// A share of the explainable gap (0 when there is none).
    pub(crate) fn share(&self, e: f64) -> f64 {
        if self.explainable > 0.0 {
            e / self.explainable
        } else {
            0.0
        }
    }
}

/// The candidates, best held-out gap closure first, the untestable ones last.
pub(crate) fn rank(cols: &Columns, rows: &Rows, spans: &Spans, fits: &Fits) -> Vec<Candidate> {
    let refs: Vec<&[[f64; NR]]> = cols.cols.iter().map(|c| c.v.as_slice()).collect();
    let n_fit_rows = fits.bank.fit.rows as f64;
    // effective sample count for the BIC: rows over the baseline residual's correlation
    let n_eff = (n_fit_rows
        / corr_length(
            &rows.y,
            &rows.usable,
            &refs,
            &fits.base_fit,
            spans.first..spans.fit_end,
        ))
    .max(1.0);
    let mut ranking: Vec<Candidate> = fits
        .cand_fits
        .iter()
        .map(|(effect, ci, f)| candidate(*effect, ci, f, cols, rows, fits, n_eff))
        .collect();
    // coherence: single-column candidates against each other, rate projected out
    for i in 0..ranking.len() {
        for j in 0..ranking.len() {
            if i == j {
                continue;
            }
            let (a, b) = (cols.of(ranking[i].effect), cols.of(ranking[j].effect));
            if a.len() == 1
                && b.len() == 1
                && fits.bank.partial_corr(a[0], b[0], &cols.base_cols).abs() >= COHERENT
            {
                let other = ranking[j].effect;
                ranking[i].coherent_with.push(other);
            }
        }
    }
    // best first, a closure that is not a number last (a total order: a comparator that
    // calls NaN equal to everything is not one, and the sort may panic on it)
    ranking.sort_by(|a, b| nan_low(b.gap_closure).total_cmp(&nan_low(a.gap_closure)));
    ranking.extend(cols.untestable.iter().map(|(effect, why)| Candidate {
        effect: *effect,
        size: None,
        size_sigma: None,
        gap_closure: 0.0,
        significant: false,
        energy_fraction: 0.0,
        delta_bic: 0.0,
        residual_explainable: 0.0,
        coherent_with: Vec::new(),
        untestable: Some(why.clone()),
        beat_hz: None,
    }));
    ranking
}

/// One tested candidate: its size (the vibration's as an amplitude), significance, gap
/// closure, ΔBIC and what the catch-all still finds on top of it.
fn candidate(
    effect: Effect,
    ci: &[usize],
    f: &Fit,
    cols: &Columns,
    rows: &Rows,
    fits: &Fits,
    n_eff: f64,
) -> Candidate {
    let (e0, gpd) = (fits.e0, rows.gpd);
    let k0 = cols.base_cols.len();
    let vibration = effect.signature() == Some(Signature::Vibration);
    let (size, sigma) = if vibration {
        let (gr, gi) = (f.beta[k0], f.beta[k0 + 1]);
        let amp = gr.hypot(gi);
        let sig = if amp > 0.0 {
            ((gr * f.sigma[k0]).powi(2) + (gi * f.sigma[k0 + 1]).powi(2)).sqrt() / amp
        } else {
            f.sigma[k0].max(f.sigma[k0 + 1])
        };
        (amp / gpd, sig / gpd)
    } else {
        (f.beta[k0], f.sigma[k0])
    };
    let efrac = if e0 > 0.0 { (e0 - f.e_hold) / e0 } else { 0.0 };
    let dbic = n_eff * (f.e_fit / fits.base_fit.e_fit).ln() + ci.len() as f64 * n_eff.ln();
    // residual check: the catch-all on top of the candidate
    let both = fits.bank.fit(
        &cols.with(
            &ci.iter()
                .copied()
                .chain(cols.ca_idx.iter().copied())
                .collect::<Vec<_>>(),
        ),
    );
    Candidate {
        effect,
        size: Some(size),
        size_sigma: Some(sigma),
        gap_closure: fits.share(e0 - f.e_hold),
        significant: sigma > 0.0 && size.abs() / sigma >= T_SIG && efrac >= GAP_MIN,
        energy_fraction: efrac,
        delta_bic: dbic,
        residual_explainable: fits.share(f.e_hold - both.e_hold).max(0.0),
        coherent_with: Vec::new(),
        untestable: None,
        beat_hz: vibration.then_some(cols.beat),
    }
}
