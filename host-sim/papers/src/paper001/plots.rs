//! Figs 3–4: A(λ) and B(λ) with stability and the free system's backbone parabolas, drawn
//! with the project's plotting kit ([`paragyro_simulator::plot`]).

use std::path::Path;

use anyhow::{Context, Result};
use paragyro_simulator::plot::{Clip, Line, Panel, draw_panel, figure_sized, grid, split_runs};
use plotters::prelude::{RGBColor, SeriesLabelPosition};

use super::model::Params;
use super::regimes::{LAMBDA_HI, LAMBDA_LO};
use crate::numerics::BranchPoint;

const DARK: RGBColor = RGBColor(20, 30, 100);
const LIGHT: RGBColor = RGBColor(160, 185, 235);
const GREY: RGBColor = RGBColor(150, 150, 150);

pub(super) fn plot_fig(
    path: &Path,
    title: &str,
    p: &Params,
    br: &[Vec<BranchPoint>],
) -> Result<()> {
    let (root, body) = figure_sized(path, (1400, 700), title)?;
    for (ip, area) in grid(&body, 1, 2).iter().enumerate() {
        draw_panel(area, &panel(p, br, ip == 0))?;
    }
    root.present()
        .with_context(|| format!("writing {}", path.display()))?;
    Ok(())
}

/// The A(λ) (`drive`) or B(λ) panel.
fn panel(p: &Params, br: &[Vec<BranchPoint>], drive: bool) -> Panel {
    let amp = |v: &[f64; 4]| {
        if drive {
            v[0].hypot(v[1])
        } else {
            v[2].hypot(v[3])
        }
    };
    let what = if drive { "A" } else { "B" };
    let mut panel = Panel::new(
        format!(
            "{what}(λ)   (j = {}, m0 = {}, γ = {}, v0 = {}, v1 = {})",
            p.j, p.m0, p.gamma, p.v0, p.v1
        ),
        (LAMBDA_LO, LAMBDA_HI),
        (0.0, 4.0),
    );
    panel.x_desc = Some("detuning λ = (μ − 1)/ε".into());
    panel.y_desc = what.to_string();
    panel.clip = Clip::Drop;
    // backbone parabolas of the free system: c j A² = 8λ ± 4 v1
    let mut first = true;
    for c in [1.0, 3.0] {
        let signs: &[f64] = if p.v1 == 0.0 { &[1.0] } else { &[1.0, -1.0] };
        for &sg in signs {
            let pts: Vec<(f64, f64)> = (0..=200)
                .map(|k| {
                    let a = 4.0 * k as f64 / 200.0;
                    ((c * p.j * a * a - sg * 4.0 * p.v1) / 8.0, a)
                })
                .collect();
            let mut line = Line::new(pts, GREY, 1).dashed();
            if first {
                line = line.label("free regimes (m0 = 0): c·j·A² = 8λ ± 4v1, c = 1, 3");
                first = false;
            }
            panel.lines.push(line);
        }
    }
    let (mut ls, mut lu) = (Some("Lyapunov stable"), Some("unstable"));
    for b in br {
        for (stable, seg) in split_runs(b, |q| q.stable) {
            let pts: Vec<(f64, f64)> = seg.iter().map(|q| (q.p, amp(&q.v))).collect();
            let mut line = if stable {
                Line::new(pts, DARK, 3)
            } else {
                Line::new(pts, LIGHT, 2)
            };
            if let Some(l) = if stable { ls.take() } else { lu.take() } {
                line = line.label(l);
            }
            panel.lines.push(line);
        }
    }
    // the parabolas first, then the unstable branches, the stable ones on top
    panel
        .lines
        .sort_by_key(|l| u8::from(l.color == DARK) + 2 * u8::from(l.color != GREY));
    panel.legend = Some(SeriesLabelPosition::UpperLeft);
    panel
}
