//! A rotary's measured angle error (the HTM50200 paper): when the NC word commands `c`, the axis
//! stands at `c + Δ(clamp(c))`. IK needs the inverse, `c` with `c + Δ(c) = wanted`, to 1e-9°.

/// Δ as a polynomial, stored in radians (converted once from the profile's degrees).
#[derive(Clone, Debug, PartialEq)]
pub struct AngleError {
    /// Coefficients k_i of Δ(x) = Σ k_i x^i with x and Δ in radians.
    k: Vec<f64>,
    /// Fitted range in radians.
    range: (f64, f64),
    /// Coefficients and range as the profile gave them (degrees), for display and round trips.
    pub coefficients_deg: Vec<f64>,
    pub range_deg: (f64, f64),
    /// max |Δ| over the range: brackets the inverse.
    max_abs: f64,
}

impl AngleError {
    /// `coefficients`: c0, c1, … of Δ(θ) in degrees; `range`: the fitted range in degrees.
    pub fn new(coefficients: Vec<f64>, range: (f64, f64)) -> AngleError {
        let d = std::f64::consts::PI / 180.0;
        // Δ_rad(x) = d · Σ c_i (x/d)^i  ⇒  k_i = c_i · d^(1-i)
        let k = coefficients
            .iter()
            .enumerate()
            .map(|(i, c)| c * d.powi(1 - i as i32))
            .collect();
        let mut e = AngleError {
            k,
            range: (range.0 * d, range.1 * d),
            coefficients_deg: coefficients,
            range_deg: range,
            max_abs: 0.0,
        };
        e.max_abs = (0..=1000)
            .map(|i| e.poly(e.range.0 + (e.range.1 - e.range.0) * i as f64 / 1000.0).abs())
            .fold(0.0, f64::max);
        e
    }

    pub(crate) fn validate(&self) -> Result<(), String> {
        if self.k.is_empty() || self.k.len() > 12 {
            return Err("coefficients: give 1 to 12 coefficients".into());
        }
        if !self.k.iter().all(|c| c.is_finite()) {
            return Err("coefficients must be finite".into());
        }
        let (lo, hi) = self.range_deg;
        if !(lo.is_finite() && hi.is_finite() && lo < hi) {
            return Err(format!("range [{lo}, {hi}] must be finite with min < max"));
        }
        // The inverse is unique only if c + Δ(c) increases: check the slope densely.
        let n = 4000;
        for i in 0..=n {
            let x = self.range.0 + (self.range.1 - self.range.0) * i as f64 / n as f64;
            if 1.0 + self.dpoly(x) <= 0.05 {
                return Err(format!(
                    "c + Δ(c) must increase over the fitted range; its slope is {:.3} at {:.3}°",
                    1.0 + self.dpoly(x),
                    x.to_degrees()
                ));
            }
        }
        Ok(())
    }

    #[inline]
    fn poly(&self, x: f64) -> f64 {
        self.k.iter().rev().fold(0.0, |acc, c| acc * x + c)
    }

    #[inline]
    fn dpoly(&self, x: f64) -> f64 {
        let n = self.k.len();
        (1..n).rev().fold(0.0, |acc, i| acc * x + i as f64 * self.k[i])
    }

    /// Δ(word) in radians, with the word clamped into the fitted range.
    #[inline]
    pub fn delta(&self, word: f64) -> f64 {
        self.poly(word.clamp(self.range.0, self.range.1))
    }

    pub fn in_range(&self, word: f64) -> bool {
        word >= self.range.0 - 1e-12 && word <= self.range.1 + 1e-12
    }

    /// The word `c` with `c + Δ(c) = actual`: safeguarded Newton inside a bracket that must hold
    /// the root, because `c + Δ(c)` is strictly increasing (checked by `validate`).
    pub fn word_for(&self, actual: f64) -> f64 {
        let g = |c: f64| c + self.delta(c) - actual;
        let (mut lo, mut hi) = (actual - self.max_abs - 1e-9, actual + self.max_abs + 1e-9);
        let mut c = actual - self.delta(actual);
        // The rounding of `g` itself: a residual below it only chases the last bits.
        let floor = 4.0 * f64::EPSILON * (1.0 + actual.abs());
        for _ in 0..100 {
            let v = g(c);
            if v.abs() <= floor {
                return c;
            }
            if v < 0.0 {
                lo = c;
            } else {
                hi = c;
            }
            let slope = if self.in_range(c) { 1.0 + self.dpoly(c) } else { 1.0 };
            let mut next = c - v / slope;
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            }
            if (next - c).abs() <= 1e-16 * (1.0 + c.abs()) || hi - lo <= 1e-16 * (1.0 + c.abs()) {
                return next;
            }
            c = next;
        }
        c
    }
}
