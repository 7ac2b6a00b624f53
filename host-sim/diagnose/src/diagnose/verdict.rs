//! Stage 4, the verdict. `none`: nothing closes at least [`GAP_MIN`] of the held-out
//! baseline energy (of the calibrated model) and that residual is at the record's own noise
//! (at most [`NONE_NOISE_MAX`] × its noise per row), unless the parameter face names an
//! effect (anisodamping against a rate table). An effect: the best candidate is significant and closes at least
//! [`SHARE_MIN`] of what the floor closes, and it (with a second effect on top, if one adds
//! at least [`SECOND_MIN`]) leaves at most [`UNEXPLAINED_MAX`] of the gap above the noise,
//! and no row holding a share of the gap mostly unexplained. `unknown`: a gap no library
//! effect explains.

use std::fmt;
use std::str::FromStr;

use paragyro_simulator::effects::Effect;
use serde::{Deserialize, Serialize};

use super::calibrate::ParameterFace;
use super::columns::Columns;
use super::lsq::{Fit, row_energy};
use super::rank::Fits;
use super::report::Candidate;
use super::rows::{Rows, Spans};
use super::{
    GAP_MIN, NOISE_ROW_SCATTER_OWN, NONE_NOISE_MAX, NR, ROW_GAP_MIN, ROW_GAP_SHARE,
    ROW_SCATTER_SIGMAS, ROW_UNEXPLAINED_MAX, SECOND_MIN, SHARE_MIN, T_SIG, UNEXPLAINED_MAX,
};

/// A one-word answer: `none`, `unknown` or an effect's name (report.json's `verdict` and
/// `closest_library_effect`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(into = "String", try_from = "String")]
pub enum Answer {
    /// No significant gap.
    None,
    /// A library effect.
    Effect(Effect),
    /// A gap that no library effect explains.
    Unknown,
}

impl fmt::Display for Answer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.pad(match self {
            Answer::None => "none",
            Answer::Unknown => "unknown",
            Answer::Effect(e) => e.name(),
        })
    }
}

impl FromStr for Answer {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "none" => Ok(Answer::None),
            "unknown" => Ok(Answer::Unknown),
            e => e
                .parse()
                .map(Answer::Effect)
                .map_err(|e| format!("not a verdict: {e}, none, unknown")),
        }
    }
}

impl From<Answer> for String {
    fn from(a: Answer) -> String {
        a.to_string()
    }
}

impl TryFrom<String> for Answer {
    type Error = String;

    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

/// A second effect on top of the verdict's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Secondary {
    /// The effect.
    pub effect: Effect,
    /// The share of the explainable gap it adds to the first one.
    pub added_closure: f64,
}

/// The verdict of a diagnosis; in report.json its `verdict` and `secondary` keys.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(into = "VerdictWire", try_from = "VerdictWire")]
pub enum Verdict {
    /// No significant gap.
    None,
    /// A library effect explains the gap (with a second one, if it adds enough).
    Effects {
        /// The effect that explains most of the gap.
        primary: Effect,
        /// A second effect on top.
        secondary: Option<Secondary>,
    },
    /// A gap exists but no library effect explains it.
    Unknown,
}

impl Verdict {
    /// The one-word answer (`none`, `unknown` or the primary effect).
    pub fn answer(&self) -> Answer {
        match self {
            Verdict::None => Answer::None,
            Verdict::Unknown => Answer::Unknown,
            Verdict::Effects { primary, .. } => Answer::Effect(*primary),
        }
    }

    /// The effects named: none, the primary, or the primary and the secondary.
    pub fn effects(&self) -> Vec<Effect> {
        match self {
            Verdict::None | Verdict::Unknown => Vec::new(),
            Verdict::Effects { primary, secondary } => std::iter::once(*primary)
                .chain(secondary.as_ref().map(|s| s.effect))
                .collect(),
        }
    }

    /// The second effect, if any.
    pub fn secondary(&self) -> Option<&Secondary> {
        match self {
            Verdict::Effects { secondary, .. } => secondary.as_ref(),
            Verdict::None | Verdict::Unknown => None,
        }
    }
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.answer().fmt(f)
    }
}

/// The verdict as report.json has it: two keys.
#[derive(Serialize, Deserialize)]
struct VerdictWire {
    verdict: Answer,
    secondary: Option<Secondary>,
}

impl From<Verdict> for VerdictWire {
    fn from(v: Verdict) -> Self {
        VerdictWire {
            verdict: v.answer(),
            secondary: v.secondary().cloned(),
        }
    }
}

impl TryFrom<VerdictWire> for Verdict {
    type Error = String;

    fn try_from(w: VerdictWire) -> Result<Self, String> {
        match (w.verdict, w.secondary) {
            (Answer::Effect(primary), secondary) => Ok(Verdict::Effects { primary, secondary }),
            (Answer::None, None) => Ok(Verdict::None),
            (Answer::Unknown, None) => Ok(Verdict::Unknown),
            (a, Some(s)) => Err(format!(
                "a secondary effect ({}) with the verdict '{a}'",
                s.effect
            )),
        }
    }
}

/// What the verdict stage decided, and the fit of the verdict's columns.
pub(crate) struct Decision {
    pub verdict: Verdict,
    /// The verdict before the residual checks (the closest library effect, or none/unknown).
    pub closest: Answer,
    /// The verdict's columns (empty for none/unknown).
    pub verdict_cols: Vec<usize>,
    /// The fit of exactly the baseline and the verdict's columns.
    pub after_fit: Fit,
    /// Share of the held-out gap above the noise the closest answer leaves unexplained.
    pub unexplained: f64,
    /// Rows holding a share of the gap that the closest answer leaves mostly unexplained.
    pub unexplained_rows: Vec<usize>,
    /// Explainable share of the held-out baseline energy.
    pub gap_fraction: f64,
    /// Held-out gap above the floor, before and after the verdict's effect(s).
    pub gap_before: f64,
    pub gap_after: f64,
    /// Held-out baseline energy per row over the record's own noise per row.
    pub residual_over_noise: f64,
}

/// Decides the verdict from the ranking.
pub(crate) fn decide(
    cols: &Columns,
    rows: &Rows,
    spans: &Spans,
    fits: &Fits,
    ranking: &[Candidate],
    face: &ParameterFace,
    row_noise: &[f64; NR],
) -> Decision {
    let (e0, explainable) = (fits.e0, fits.explainable);
    let gap_fraction = if e0 > 0.0 { explainable / e0 } else { 0.0 };
    // the record's own noise per row (its noise energy ratio × this record's rows' at the
    // reference density, their mean: `noise::row_noise`)
    let noise_row = row_noise.iter().sum::<f64>() / NR as f64 * face.noise_energy_ratio;
    let hold_rows = fits.bank.hold.rows.max(1) as f64;
    let residual_over_noise = e0 / hold_rows / noise_row;
    // a parameter-face effect the calibration names (anisodamping against a rate table)
    let face_named = face
        .hypotheses
        .iter()
        .find(|h| h.status == "named")
        .and_then(|h| h.name.parse::<Effect>().ok());
    let closest = match ranking.first() {
        _ if gap_fraction < GAP_MIN && residual_over_noise <= NONE_NOISE_MAX => {
            face_named.map_or(Answer::None, Answer::Effect)
        }
        _ if gap_fraction < GAP_MIN => Answer::Unknown,
        Some(b) if b.significant && b.gap_closure >= SHARE_MIN => Answer::Effect(b.effect),
        _ => Answer::Unknown,
    };
    let verdict = match closest {
        Answer::None => Verdict::None,
        Answer::Unknown => Verdict::Unknown,
        Answer::Effect(primary) => Verdict::Effects {
            primary,
            secondary: secondary(primary, cols, fits, ranking),
        },
    };
    let verdict_cols: Vec<usize> = verdict
        .effects()
        .into_iter()
        .flat_map(|e| cols.of(e))
        .collect();
    let after_fit = fits.bank.fit(&cols.with(&verdict_cols));
    // the verdict must explain the gap above the noise, not just most of what the floor does
    let noise_e = noise_row * hold_rows;
    let unexplained = if e0 > noise_e {
        ((after_fit.e_hold - noise_e) / (e0 - noise_e)).max(0.0)
    } else {
        0.0
    };
    let unexplained_rows = if verdict_cols.is_empty() {
        Vec::new()
    } else {
        let own: [f64; NR] = std::array::from_fn(|i| row_noise[i] * face.noise_energy_ratio);
        unexplained_rows(
            cols,
            rows,
            spans,
            fits,
            &after_fit,
            &own,
            face.noise_energy_ratio,
        )
    };
    let (verdict, verdict_cols, after_fit) = if !verdict_cols.is_empty()
        && (unexplained > UNEXPLAINED_MAX || !unexplained_rows.is_empty())
    {
        (Verdict::Unknown, Vec::new(), fits.bank.fit(&cols.base_cols))
    } else {
        (verdict, verdict_cols, after_fit)
    };
    Decision {
        residual_over_noise,
        gap_after: (after_fit.e_hold - fits.e_floor).max(0.0),
        gap_before: explainable,
        verdict,
        closest,
        verdict_cols,
        after_fit,
        unexplained,
        unexplained_rows,
        gap_fraction,
    }
}

/// A second effect on top of `primary`: the one adding the most (at least [`SECOND_MIN`]
/// of the explainable gap, significant).
fn secondary(
    primary: Effect,
    cols: &Columns,
    fits: &Fits,
    ranking: &[Candidate],
) -> Option<Secondary> {
    let c1 = cols.of(primary);
    let e1 = fits.of(primary).map_or(fits.e0, |f| f.e_hold);
    let mut best: Option<Secondary> = None;
    for c in ranking.iter().skip(1).filter(|c| c.untestable.is_none()) {
        let c2 = cols.of(c.effect);
        let f = fits
            .bank
            .fit(&cols.with(&c1.iter().chain(c2.iter()).copied().collect::<Vec<_>>()));
        // the second effect's first coefficient, by its column (not a position the fit
        // may not hold)
        let Some(a) = c2.first().and_then(|c| f.cols.iter().position(|j| j == c)) else {
            continue;
        };
        let add = fits.share(e1 - f.e_hold);
        let tstat = f.beta[a].abs() / f.sigma[a].max(1e-300);
        if add >= SECOND_MIN
            && tstat >= T_SIG
            && best.as_ref().is_none_or(|s| add > s.added_closure)
        {
            best = Some(Secondary {
                effect: c.effect,
                added_closure: add,
            });
        }
    }
    best
}

/// The verdict must explain every row where the gap lives, not just the energy in total: a
/// row holding a share of the gap that the verdict leaves mostly unexplained means
/// something else is there (e.g. a quadratic stiffness: its drive DC and 1st quadrature).
/// Only where what the verdict leaves is above the row's own noise level (`own`, energy
/// per sample) by more than [`ROW_SCATTER_SIGMAS`] × its scatter about that level
/// ([`NOISE_ROW_SCATTER_OWN`] × ν²): near the noise, the catch-all's many columns close a
/// row's held-out energy by that much on no gap at all (an angular vibration at 1.8× its
/// limit, fitted at 36.3 ± 1.0 °/s, left its drive 1st quadrature at 1.77
/// against the catch-all's 1.65 and its own level 1.78, and read `unknown`).
fn unexplained_rows(
    cols: &Columns,
    rows: &Rows,
    spans: &Spans,
    fits: &Fits,
    after_fit: &Fit,
    own: &[f64; NR],
    nu2: f64,
) -> Vec<usize> {
    let refs: Vec<&[[f64; NR]]> = cols.cols.iter().map(|c| c.v.as_slice()).collect();
    let energy = |f: &Fit| row_energy(f, &rows.y, &refs, &rows.usable, spans.hold.clone());
    let (e_b, e_a, e_f) = (
        energy(&fits.base_fit),
        energy(after_fit),
        energy(&fits.floor_fit),
    );
    let g0: Vec<f64> = (0..NR).map(|i| e_b[i] - e_f[i].min(e_a[i])).collect();
    let tot: f64 = g0.iter().map(|v| v.max(0.0)).sum();
    (0..NR)
        .filter(|&i| {
            let ga = e_a[i] - e_f[i].min(e_a[i]);
            g0[i] > ROW_GAP_SHARE * tot
                && g0[i] > ROW_GAP_MIN
                && ga > ROW_UNEXPLAINED_MAX * g0[i]
                && e_a[i] - own[i] > ROW_SCATTER_SIGMAS * NOISE_ROW_SCATTER_OWN[i] * nu2
        })
        .collect()
}
