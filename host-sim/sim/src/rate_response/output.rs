//! The report's files: report.json, report.md and the plots.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use plotters::prelude::*;

use super::{AllanFigures, Report, T0_S};
use crate::plot::*;
use crate::trace::TraceRow;

/// Writes report.json and report.md; returns their names.
pub fn write_text(dir: &Path, r: &Report) -> Result<Vec<String>> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let json = serde_json::to_string_pretty(r)?;
    std::fs::write(dir.join("report.json"), json)?;
    std::fs::write(dir.join("report.md"), markdown(r))?;
    Ok(vec!["report.json".into(), "report.md".into()])
}

fn opt(v: Option<f64>, unit: &str) -> String {
    v.map_or("—".into(), |x| format!("{x:.1} {unit}"))
}

/// An Allan record's cell: ARW, bias instability, and the rate's zero's own deviation at
/// the minimum's τ beside the rate's there.
fn allan_cell(f: &AllanFigures) -> String {
    format!(
        "{:.3} °/√h / {:.2} °/h (minimum {:.2} m°/s at τ = {:.*} s, the rate's zero alone {:.2} m°/s there)",
        f.arw_deg_rth,
        f.bias_instability_deg_h,
        f.bias_instability_deg_h * 0.664 / 3.6,
        if f.tau_min_s < 10.0 { 2 } else { 0 },
        f.tau_min_s,
        f.zero_adev_at_min_dps * 1e3
    )
}

/// The datasheet table beside the rate-grade figures (issue 10).
pub fn markdown(r: &Report) -> String {
    let mut s = String::new();
    let n = &r.noise;
    let _ = writeln!(
        s,
        "# Rate channel on the simulated device ({}, seed {})\n",
        r.precision, r.seed
    );
    s.push_str("| quantity | simulated device | rate grade (target) |\n|---|---|---|\n");
    let bw = opt(r.frequency.bandwidth_3db_hz, "Hz");
    let _ = writeln!(s, "| bandwidth (−3 dB, chirp) | {bw} | > 70 Hz |");
    let _ = writeln!(
        s,
        "| 100 °/s step: max error from 25 ms | {:.2} % of step | ≤ 1 % |",
        r.step.max_err_after_25ms_pct
    );
    let _ = writeln!(
        s,
        "| rate noise (same bandwidth) | {:.3} °/s rms; CRLB {:.3} (same G), {:.3} (brick wall); ratio {:.2} / {:.2} | ≤ 2× CRLB |",
        n.noise_std_dps,
        n.crlb_std_same_g_dps,
        n.crlb_std_brickwall_dps,
        n.ratio_same_g,
        n.ratio_brickwall
    );
    let _ = writeln!(
        s,
        "| deterministic error (noise-free run, rms) | {:.3} °/s | — |",
        n.model_err_rms_dps
    );
    let _ = writeln!(
        s,
        "| noise density (CRLB, low f) | {:.2e} °/s/√Hz (ARW {:.2e} °/√h) | ARW > 0.5 °/√h |",
        n.crlb_density_dps_rthz, n.crlb_arw_deg_rth
    );
    for a in &r.allan {
        let _ = writeln!(
            s,
            "| ARW / bias instability at {} °/s ({} s, from {} s after the start-up, slow RLS λ = {}) | {} | > 0.5 °/√h / 10–1000 °/h |",
            a.rate_dps,
            a.duration_s,
            a.settle_s,
            a.forgetting,
            allan_cell(&a.figures)
        );
        if let Some(f) = &a.from_start_up {
            let _ = writeln!(
                s,
                "| the same from the start-up (the rate's zero converging) | {} | |",
                allan_cell(f)
            );
        }
        if let Some(f) = &a.after_warm_start {
            let _ = writeln!(
                s,
                "| the same from a warm start (its snapshot at {} s) | {} | |",
                a.settle_s,
                allan_cell(f)
            );
        }
    }
    let _ = writeln!(
        s,
        "| scale-factor error (±{} °/s) | {:.0} ppm | 0.1–1 % (target ≤ 0.1 %) |",
        r.ramp.full_scale_dps, r.ramp.scale_factor_err_ppm
    );
    let _ = writeln!(
        s,
        "| nonlinearity | {:.0} ppm FS | ≤ 0.1 % FS |",
        r.ramp.nonlinearity_ppm_fs
    );
    let _ = writeln!(
        s,
        "| g-sensitivity (x, y) | {:.4}, {:.4} °/s/g | — |",
        r.g_sensitivity.dps_per_g_x, r.g_sensitivity.dps_per_g_y
    );
    let _ = writeln!(
        s,
        "| full scale (validity flag) | 1000 °/s (configured) | 50–1000 °/s |\n"
    );
    s.push_str("| sine | gain | phase | error rms | resets | slow θ max dev |\n|---|---|---|---|---|---|\n");
    for x in &r.sines {
        let _ = writeln!(
            s,
            "| {} Hz ±{} °/s | {:.3} | {:.1}° | {:.2} °/s | {} | {:.1} σ |",
            x.f_hz,
            x.amplitude_dps,
            x.gain,
            x.phase_deg,
            x.err_rms_dps,
            x.resets,
            x.slow_theta_max_dev_sigma
        );
    }
    let _ = writeln!(
        s,
        "\nCovariance resets: step {}, chirp {}, ramp {}. Slow θ after the step: max {:.1} σ of its steady-state scatter. Settling to 1 %: {}.",
        r.step.resets,
        r.frequency.resets,
        r.ramp.resets,
        r.step.slow_theta_max_dev_sigma,
        opt(r.step.settle_1pct_ms, "ms")
    );
    s
}

/// step.png, bode.png, sines.png, ramp.png (and allan.png).
pub fn write_plots(
    dir: &Path,
    r: &Report,
    step: &[TraceRow],
    sines: &[Vec<TraceRow>],
    ramp: &[TraceRow],
) -> Result<Vec<String>> {
    let mut out = Vec::new();
    let rate_panel = |cap: String, tr: &[TraceRow], t0: f64, t1: f64| {
        let rows: Vec<&TraceRow> = tr.iter().filter(|x| x.t_s >= t0 && x.t_s <= t1).collect();
        let (lo, hi) = min_max(rows.iter().flat_map(|x| [x.rate_dps_true, x.rate_dps_est]))
            .unwrap_or((0.0, 1.0));
        let pad = 0.05 * (hi - lo).max(1.0);
        let mut p = Panel::new(cap, (t0, t1), (lo - pad, hi + pad));
        p.x_desc = Some("t, s".into());
        p.y_desc = "rate, °/s".into();
        p.lines.push(
            Line::new(
                rows.iter().map(|x| (x.t_s, x.rate_dps_true)).collect(),
                BLACK,
                2,
            )
            .label("true"),
        );
        p.lines.push(
            Line::new(
                rows.iter().map(|x| (x.t_s, x.rate_dps_est)).collect(),
                RED,
                2,
            )
            .label("fast channel"),
        );
        p.lines.push(
            Line::new(
                rows.iter().map(|x| (x.t_s, x.rate_dps_slow)).collect(),
                BLUE,
                1,
            )
            .dashed()
            .label("slow"),
        );
        p.legend = Some(SeriesLabelPosition::LowerRight);
        p
    };
    {
        let path = dir.join("step.png");
        let (root, body) = figure(&path, "100 °/s step")?;
        let areas = grid(&body, 1, 2);
        draw_panel(
            &areas[0],
            &rate_panel("step".into(), step, T0_S - 0.05, T0_S + 0.15),
        )?;
        draw_panel(
            &areas[1],
            &rate_panel("over 1.5 s".into(), step, T0_S - 0.5, T0_S + 1.5),
        )?;
        root.present()?;
        out.push("step.png".into());
    }
    {
        let path = dir.join("bode.png");
        let (root, body) = figure(&path, "Frequency response (chirp)")?;
        let areas = grid(&body, 2, 1);
        let pts = &r.frequency.points;
        let x = (r.frequency.f_start_hz.log10(), r.frequency.f_end_hz.log10());
        let mut m = Panel::new("magnitude".into(), x, (-12.0, 3.0));
        m.y_desc = "dB".into();
        m.x_desc = Some("log10 f, Hz".into());
        m.lines.push(Line::new(
            pts.iter().map(|p| (p.f_hz.log10(), p.mag_db)).collect(),
            RED,
            2,
        ));
        m.hlines.push((-3.0, BLACK, "−3 dB".into()));
        if let Some(bw) = r.frequency.bandwidth_3db_hz {
            m.marked_x.push((bw.log10(), format!("{bw:.0} Hz")));
        }
        draw_panel(&areas[0], &m)?;
        let mut ph = Panel::new("phase".into(), x, (-360.0, 20.0));
        ph.y_desc = "deg".into();
        ph.x_desc = Some("log10 f, Hz".into());
        ph.lines.push(Line::new(
            pts.iter().map(|p| (p.f_hz.log10(), p.phase_deg)).collect(),
            RED,
            2,
        ));
        draw_panel(&areas[1], &ph)?;
        root.present()?;
        out.push("bode.png".into());
    }
    {
        let path = dir.join("sines.png");
        let (root, body) = figure(&path, "Sines of the rate")?;
        let areas = grid(&body, sines.len().max(1), 1);
        for (i, (tr, res)) in sines.iter().zip(&r.sines).enumerate() {
            let span = (4.0 / res.f_hz).max(0.08);
            let cap = format!("{} Hz ±{} °/s", res.f_hz, res.amplitude_dps);
            draw_panel(
                &areas[i],
                &rate_panel(cap, tr, T0_S + 0.5, T0_S + 0.5 + span),
            )?;
        }
        root.present()?;
        out.push("sines.png".into());
    }
    {
        let path = dir.join("ramp.png");
        let (root, body) = figure(&path, "±300 °/s ramp")?;
        draw_panel(
            &body,
            &rate_panel("ramp".into(), ramp, T0_S - 0.5, T0_S + 15.5),
        )?;
        root.present()?;
        out.push("ramp.png".into());
    }
    if !r.allan.is_empty() {
        allan_plot(&dir.join("allan.png"), r)?;
        out.push("allan.png".into());
    }
    Ok(out)
}

/// allan.png: the static runs' Allan deviations (their records after the settle).
fn allan_plot(path: &Path, r: &Report) -> Result<()> {
    let (root, body) = figure(path, "Allan deviation of the fast rate")?;
    let all = r.allan.iter().flat_map(|a| a.tau_s.iter().copied());
    let (t0, t1) = min_max(all).unwrap_or((0.002, 1.0));
    let ys = r
        .allan
        .iter()
        .flat_map(|a| a.adev_dps.iter().map(|v| v.log10()));
    let (y0, y1) = min_max(ys).unwrap_or((-4.0, 0.0));
    // the zero's curves down to 1.5 decades below the rate's
    let floor = y0 - 1.5;
    let zs = r
        .allan
        .iter()
        .flat_map(|a| a.zero_adev_dps.iter().map(|v| v.log10()))
        .filter(|v| *v >= floor);
    let y0 = min_max(zs).map_or(y0, |(z0, _)| z0.min(y0));
    let mut p = Panel::new(
        "ADEV".into(),
        (t0.log10(), t1.log10()),
        (y0 - 0.2, y1 + 0.2),
    )
    .log_y();
    p.x_desc = Some("log10 τ, s".into());
    p.y_desc = "°/s".into();
    for (a, c) in r.allan.iter().zip([RED, BLUE]) {
        let pts = a
            .tau_s
            .iter()
            .zip(&a.adev_dps)
            .map(|(t, v)| (t.log10(), v.log10()))
            .collect();
        p.lines.push(Line::new(pts, c, 2).label(format!(
            "{} °/s, from {} s after the start-up",
            a.rate_dps, a.settle_s
        )));
        let zero = a
            .tau_s
            .iter()
            .zip(&a.zero_adev_dps)
            .map(|(t, v)| (t.log10(), v.log10()))
            .filter(|(_, v)| *v >= y0)
            .collect();
        p.lines.push(
            Line::new(zero, c, 1)
                .dashed()
                .label(format!("{} °/s: the rate's zero alone", a.rate_dps)),
        );
    }
    p.legend = Some(SeriesLabelPosition::UpperRight);
    draw_panel(&body, &p)?;
    root.present()?;
    Ok(())
}
