//! `averaged_sweep.png`: |B| and |A| against the pump frequency for both ωy², drawn with
//! the project's plotting kit ([`paragyro_simulator::plot`]).

use std::path::Path;

use anyhow::{Context, Result};
use paragyro_simulator::plot::{
    Arrow, Line, Marker, MarkerKind, Panel, TAB10, draw_panel, figure_sized, grid, split_runs,
};
use plotters::prelude::{RGBAColor, RGBColor, SeriesLabelPosition};

use super::model::pump_khz;
use super::report::{Case, SWEEP_HI, SWEEP_LO};
use crate::complex::CplxExt;

/// Which amplitude a panel shows.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Amp {
    /// Sense |B| (top panel).
    B,
    /// Drive |A| (bottom panel).
    A,
}

impl Amp {
    fn of(self, v: &[f64; 4]) -> f64 {
        match self {
            Amp::B => v[2].hypot(v[3]),
            Amp::A => v[0].hypot(v[1]),
        }
    }
}

pub(super) fn plot_sweep(
    path: &Path,
    cases: &[Case],
    band: (f64, f64),
    floquet: Option<(f64, f64)>,
) -> Result<()> {
    let (root, body) = figure_sized(
        path,
        (1400, 1100),
        "Seed 000 gyro (Table 2), averaged slow flow: response vs pump frequency",
    )?;
    let areas = grid(&body, 2, 1);
    for (area, amp) in areas.iter().zip([Amp::B, Amp::A]) {
        draw_panel(area, &panel(cases, amp, band, floquet))?;
    }
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// One panel: the rest state, the branches (solid stable, dashed unstable), the stable
/// operating states, the sweeps (every 10th point) and their jumps.
fn panel(cases: &[Case], amp: Amp, band: (f64, f64), floquet: Option<(f64, f64)>) -> Panel {
    let x = (pump_khz(SWEEP_LO), pump_khz(SWEEP_HI));
    let ymax = cases
        .iter()
        .flat_map(|c| c.branches.iter().flatten())
        .fold(0.0f64, |m, p| m.max(amp.of(&p.v)));
    let (caption, y_desc) = match amp {
        Amp::B => ("sense |B| (µm)", "|B| (µm)"),
        Amp::A => ("drive |A| (µm)", "|A| (µm)"),
    };
    let mut p = Panel::new(caption.into(), x, (0.0, 1.06 * ymax.max(1.0)));
    p.x_desc = Some("pump frequency 2ω·ω0/2π (kHz)".into());
    p.y_desc = y_desc.into();
    let (lo, hi) = (pump_khz(band.0), pump_khz(band.1));
    let shade = RGBAColor(120, 120, 120, 0.18);
    p.bands.push(paragyro_simulator::plot::Band {
        x0: lo,
        x1: hi,
        color: shade,
    });
    let label = match floquet {
        Some(f) => format!(
            "rest state unstable: {lo:.3}–{hi:.3} kHz (Floquet {:.3}–{:.3})",
            pump_khz(f.0),
            pump_khz(f.1)
        ),
        None => format!("rest state unstable: {lo:.3}–{hi:.3} kHz"),
    };
    p.band_labels.push((label, shade));
    for (name, w2) in [("ω = √1.0265", 1.0265f64), ("ω = √1.03", 1.03)] {
        let label = if amp == Amp::B { name } else { "" };
        p.marked_x.push((pump_khz(w2.sqrt()), label.to_string()));
    }
    // rest state: solid outside the band, dashed inside
    let grey = RGBColor(90, 90, 90);
    p.lines
        .push(Line::new(vec![(x.0, 0.0), (lo, 0.0)], grey, 2));
    p.lines
        .push(Line::new(vec![(hi, 0.0), (x.1, 0.0)], grey, 2));
    p.lines
        .push(Line::new(vec![(lo, 0.0), (hi, 0.0)], grey, 1).dashed());
    let colors = [TAB10[0], TAB10[3]];
    for (ic, c) in cases.iter().enumerate() {
        add_case(&mut p, c, colors[ic % 2], amp);
    }
    p.legend = (amp == Amp::A).then_some(SeriesLabelPosition::UpperLeft);
    p
}

/// The branches, operating states, sweep markers and jump arrows of one ωy².
fn add_case(p: &mut Panel, c: &Case, col: RGBColor, amp: Amp) {
    let mut lab_s = Some(format!("ωy² = {}: stable", c.wy2));
    let mut lab_u = Some(format!("ωy² = {}: unstable", c.wy2));
    for b in &c.branches {
        for (stable, seg) in split_runs(b, |q| q.stable) {
            let pts = seg.iter().map(|q| (pump_khz(q.p), amp.of(&q.v))).collect();
            let mut line = Line::new(pts, col, if stable { 2 } else { 1 });
            if !stable {
                line = line.dashed();
            }
            if let Some(l) = if stable { lab_s.take() } else { lab_u.take() } {
                line = line.label(l);
            }
            p.lines.push(line);
        }
    }
    for (k, st) in c.ops.iter().enumerate() {
        p.markers.push(Marker {
            x: pump_khz(st.omega),
            y: match amp {
                Amp::B => st.b.modulus(),
                Amp::A => st.a.modulus(),
            },
            kind: MarkerKind::Circle,
            color: col,
            size: 6.0,
            label: (k == 0).then(|| format!("ωy² = {}: stable state at ω = √1.0265, √1.03", c.wy2)),
        });
    }
    for (up, sw) in [(true, &c.up), (false, &c.down)] {
        let y = |q: &super::SweepPoint| match amp {
            Amp::B => q.abs_b,
            Amp::A => q.abs_a,
        };
        let mut first = true;
        for (k, q) in sw.iter().enumerate() {
            if k % 10 == 5 {
                p.markers.push(Marker {
                    x: pump_khz(q.omega),
                    y: y(q),
                    kind: if up {
                        MarkerKind::TriUp
                    } else {
                        MarkerKind::TriDown
                    },
                    color: col,
                    size: 6.0,
                    label: first.then(|| {
                        let dir = if up { "up" } else { "down" };
                        format!("ωy² = {}: {dir}-sweep from rest", c.wy2)
                    }),
                });
                first = false;
            }
            if q.jump && k > 0 {
                p.arrows.push(Arrow {
                    x: pump_khz(q.omega),
                    y0: y(&sw[k - 1]),
                    y1: y(q),
                    color: col,
                });
            }
        }
    }
}
