//! The die temperature of a scenario (`[temperature]`): a piecewise-linear profile and the
//! temperature coefficients that move the plant with it.
//!
//! ```toml
//! [temperature]
//! points = [[0.0, 25.0], [5.0, 25.0], [305.0, 35.0]]   # (t_s, °C): linear between, held outside
//! tcf_wx_ppm_k = -30.0      # frequency TCF of the drive mode, ppm/K
//! tcf_wy_ppm_k = -33.0      # frequency TCF of the sense mode, ppm/K
//! tc_damping_ppm_k = 0.0    # μx, μy (damping) per K, ppm/K
//! reference_c = 25.0        # the [plant] values hold at this temperature
//! sensor = true             # the samples carry the temperature as the board reads it
//! sensor_lsb_k = 0.1105     # its resolution (the ADXL355: 9.05 codes per K)
//! sensor_noise_k = 0.05     # its white noise, K rms
//! ```
//!
//! At temperature T the plant's ω_x, ω_y scale by (1 + TCF·(T − reference)), so ω_x² and
//! ω_y² by its square, and μx, μy by (1 + tc_damping·(T − reference)); ramps of `wx2`,
//! `wy2`, `mu_x`, `mu_y` in `[[event]]` apply first, the temperature on top.

use serde::{Deserialize, Serialize};

use super::spec::PlantSpec;

/// `[temperature]` of a scenario.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemperatureSpec {
    /// The profile: (t_s, °C) pairs in time order; linear between them, the first and
    /// last values held before and after.
    pub points: Vec<[f64; 2]>,
    /// Frequency TCF of the drive mode, ppm/K.
    #[serde(default)]
    pub tcf_wx_ppm_k: f64,
    /// Frequency TCF of the sense mode, ppm/K.
    #[serde(default)]
    pub tcf_wy_ppm_k: f64,
    /// Temperature coefficient of the damping μx, μy, ppm/K.
    #[serde(default)]
    pub tc_damping_ppm_k: f64,
    /// Temperature at which the `[plant]` values hold, °C.
    #[serde(default = "default_reference_c")]
    pub reference_c: f64,
    /// The samples carry the die temperature as the board's sensor reads it (the core
    /// then learns the coefficients and predicts the drift, core module `thermal`);
    /// false: no temperature reaches the core (the drift is followed by its walk alone).
    #[serde(default = "default_sensor")]
    pub sensor: bool,
    /// The sensor's resolution, K (the ADXL355's 9.05 codes per K).
    #[serde(default = "default_sensor_lsb_k")]
    pub sensor_lsb_k: f64,
    /// The sensor's white noise, K rms.
    #[serde(default = "default_sensor_noise_k")]
    pub sensor_noise_k: f64,
}

fn default_reference_c() -> f64 {
    25.0
}

fn default_sensor() -> bool {
    true
}

fn default_sensor_lsb_k() -> f64 {
    1.0 / 9.05
}

fn default_sensor_noise_k() -> f64 {
    0.05
}

impl TemperatureSpec {
    /// The die temperature at `t_s`, °C.
    pub fn temp_c(&self, t_s: f64) -> f64 {
        let p = &self.points;
        let Some(first) = p.first() else {
            return self.reference_c;
        };
        if t_s <= first[0] {
            return first[1];
        }
        for w in p.windows(2) {
            let ([t0, c0], [t1, c1]) = (w[0], w[1]);
            if t_s <= t1 {
                if t1 <= t0 {
                    return c1;
                }
                return c0 + (c1 - c0) * (t_s - t0) / (t1 - t0);
            }
        }
        p.last().map_or(self.reference_c, |l| l[1])
    }

    /// When the profile moves: from the start of its first segment that changes the
    /// temperature to the end of its last, s (`None`: it never changes).
    pub fn moving_s(&self) -> Option<(f64, f64)> {
        let mut moving = self
            .points
            .windows(2)
            .filter(|w| w[1][1] != w[0][1])
            .map(|w| (w[0][0], w[1][0]));
        let first = moving.next()?;
        Some(moving.fold(first, |(a, _), (_, b)| (a, b)))
    }

    /// The die temperature's rate at `t_s`, K/s (the slope of the segment).
    pub fn rate_k_per_s(&self, t_s: f64) -> f64 {
        for w in self.points.windows(2) {
            let ([t0, c0], [t1, c1]) = (w[0], w[1]);
            if t_s >= t0 && t_s < t1 && t1 > t0 {
                return (c1 - c0) / (t1 - t0);
            }
        }
        0.0
    }

    /// The sensor's reading at `t_s` given a standard normal draw `n`: the temperature
    /// plus `sensor_noise_k`·n, rounded to `sensor_lsb_k` (none: `sensor` false).
    pub fn read(&self, t_s: f64, n: f64) -> Option<f64> {
        if !self.sensor {
            return None;
        }
        let t = self.temp_c(t_s) + self.sensor_noise_k * n;
        let lsb = self.sensor_lsb_k;
        Some(if lsb > 0.0 {
            (t / lsb).round() * lsb
        } else {
            t
        })
    }

    /// The plant at temperature `temp_c` (see the module docs).
    pub fn apply(&self, p: &mut PlantSpec, temp_c: f64) {
        let dt = temp_c - self.reference_c;
        let fx = 1.0 + self.tcf_wx_ppm_k * 1e-6 * dt;
        let fy = 1.0 + self.tcf_wy_ppm_k * 1e-6 * dt;
        let fm = 1.0 + self.tc_damping_ppm_k * 1e-6 * dt;
        p.wx2 *= fx * fx;
        p.wy2 *= fy * fy;
        p.mu_x *= fm;
        p.mu_y *= fm;
    }

    /// The first problem of the spec: (field, message).
    pub(super) fn problem(&self) -> Option<(&'static str, String)> {
        if self.points.is_empty() {
            return Some(("points", "must have at least one (t_s, °C) pair".into()));
        }
        for (i, [t, c]) in self.points.iter().enumerate() {
            if !(t.is_finite() && c.is_finite()) {
                return Some(("points", format!("point #{} is not finite", i + 1)));
            }
            if !(-273.15..=1000.0).contains(c) {
                return Some((
                    "points",
                    format!("point #{}: {c} °C is not a die temperature", i + 1),
                ));
            }
        }
        if self.points.windows(2).any(|w| w[1][0] < w[0][0]) {
            return Some(("points", "must be in time order".into()));
        }
        for (name, v) in [
            ("tcf_wx_ppm_k", self.tcf_wx_ppm_k),
            ("tcf_wy_ppm_k", self.tcf_wy_ppm_k),
            ("tc_damping_ppm_k", self.tc_damping_ppm_k),
        ] {
            if !(v.is_finite() && v.abs() <= 1e4) {
                return Some((
                    name,
                    format!("must be finite and within ±1e4 ppm/K (got {v})"),
                ));
            }
        }
        if !self.reference_c.is_finite() {
            return Some(("reference_c", "must be finite".into()));
        }
        for (name, v) in [
            ("sensor_lsb_k", self.sensor_lsb_k),
            ("sensor_noise_k", self.sensor_noise_k),
        ] {
            if !(v.is_finite() && (0.0..=10.0).contains(&v)) {
                return Some((name, format!("must be within 0…10 K (got {v})")));
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn warm_up() -> TemperatureSpec {
        TemperatureSpec {
            points: vec![[0.0, 25.0], [5.0, 25.0], [305.0, 35.0]],
            tcf_wx_ppm_k: -30.0,
            tcf_wy_ppm_k: -33.0,
            tc_damping_ppm_k: 0.0,
            reference_c: 25.0,
            sensor: true,
            sensor_lsb_k: 0.1,
            sensor_noise_k: 0.0,
        }
    }

    #[test]
    fn the_profile_is_linear_between_points_and_held_outside() {
        let t = warm_up();
        assert_eq!(t.temp_c(-1.0), 25.0);
        assert_eq!(t.temp_c(3.0), 25.0);
        assert!((t.temp_c(155.0) - 30.0).abs() < 1e-12);
        assert_eq!(t.temp_c(400.0), 35.0);
        assert!((t.rate_k_per_s(100.0) - 10.0 / 300.0).abs() < 1e-15);
        assert_eq!(t.rate_k_per_s(2.0), 0.0);
    }

    #[test]
    fn a_10_k_warm_up_moves_the_squared_frequencies_by_twice_their_tcf() {
        // the issue's warm-up: ωx² −600 ppm, ωy² −660 ppm (to first order)
        let t = warm_up();
        let mut p = PlantSpec::default();
        let (wx2, wy2) = (p.wx2, p.wy2);
        t.apply(&mut p, 35.0);
        assert!((p.wx2 / wx2 - (1.0 - 300e-6) * (1.0 - 300e-6)).abs() < 1e-15);
        assert!((p.wy2 / wy2 - 1.0 + 660e-6).abs() < 2e-7);
    }

    #[test]
    fn the_profile_moves_from_its_first_change_to_its_last() {
        let mut t = warm_up();
        assert_eq!(t.moving_s(), Some((5.0, 305.0)));
        t.points.extend([[310.0, 35.0], [320.0, 30.0]]);
        assert_eq!(t.moving_s(), Some((5.0, 320.0)));
        t.points = vec![[0.0, 25.0], [10.0, 25.0]];
        assert_eq!(t.moving_s(), None);
    }

    #[test]
    fn the_sensor_reads_the_profile_in_its_codes_or_not_at_all() {
        let mut t = warm_up();
        // 30 °C at 155 s; 0.1 K codes; a 1σ draw of 0.05 K noise
        t.sensor_noise_k = 0.05;
        let r = t.read(155.0, 1.0).unwrap();
        assert!((r - 30.1).abs() < 1e-9, "{r}");
        assert!((t.read(155.0, 0.0).unwrap() - 30.0).abs() < 1e-9);
        t.sensor = false;
        assert_eq!(t.read(155.0, 0.0), None);
    }

    #[test]
    fn bad_specs_name_their_field() {
        let mut t = warm_up();
        t.points = vec![[5.0, 25.0], [1.0, 30.0]];
        assert_eq!(t.problem().map(|p| p.0), Some("points"));
        let mut t = warm_up();
        t.tcf_wy_ppm_k = f64::NAN;
        assert_eq!(t.problem().map(|p| p.0), Some("tcf_wy_ppm_k"));
        let mut t = warm_up();
        t.sensor_noise_k = -0.1;
        assert_eq!(t.problem().map(|p| p.0), Some("sensor_noise_k"));
        assert!(warm_up().problem().is_none());
    }
}
