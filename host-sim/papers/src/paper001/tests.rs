use super::*;
use crate::numerics::fd_jacobian;

#[test]
fn analytic_jacobian_matches_finite_differences() {
    let p = Params {
        gamma: 0.3,
        v0: 0.2,
        ..Params::fig4()
    };
    for s in [[0.3, -1.2, 0.7, 0.4], [1.5, 0.2, -0.9, 2.0]] {
        let ja = eq22_jacobian(&p, 0.7, &s);
        let jf = fd_jacobian(&|x| eq22(&p, 0.7, x), &s);
        for r in 0..4 {
            for c in 0..4 {
                assert!(
                    (ja[r][c] - jf[r][c]).abs() < 1e-7,
                    "{r},{c}: {} vs {}",
                    ja[r][c],
                    jf[r][c]
                );
            }
        }
        // trace = −16γ
        let tr: f64 = (0..4).map(|i| ja[i][i]).sum();
        assert!((tr + 16.0 * p.gamma).abs() < 1e-12);
    }
}

#[test]
fn plane_regime_and_backbone_of_fig3() {
    // v1 = v0 = γ = 0: the plane regime B = 0, A = m0/(2|λ|), and spatial regimes with
    // A² = 8λ/(c j)
    let p = Params::fig3();
    for lam in [-0.4, 0.3, 1.0] {
        let pts = stationary_points(&p, lam);
        assert!(
            pts.iter()
                .any(|s| s.b < 1e-9 && (s.a - p.m0 / (2.0 * lam.abs())).abs() < 1e-10),
            "plane regime at {lam}: {pts:?}"
        );
        for s in pts.iter().filter(|s| s.b > 1e-6) {
            let c = p.j * s.a * s.a / (8.0 * lam);
            assert!(
                (c - 1.0).abs() < 1e-9 || (3.0 * c - 1.0).abs() < 1e-9,
                "{lam}: {s:?}"
            );
        }
    }
    // λ < 0: only the plane regime
    assert_eq!(stationary_points(&p, -0.4).len(), 1);
}

#[test]
fn slow_state_round_trip() {
    let p = Params::fig4();
    let s = [0.3, -1.1, 0.8, 0.25];
    for tau in [0.0, 1.3, 1234.5] {
        let z = state_from_slow(&p, 0.7, tau, &s);
        let b = slow_from_state(&p, 0.7, tau, &z);
        for i in 0..4 {
            assert!((b[i] - s[i]).abs() < 1e-12);
        }
    }
}
