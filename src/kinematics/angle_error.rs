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
    /// A bound on |Δ''| over the range: how far a Newton step can land from the root.
    max_curve: f64,
    /// The inverse over the range, to 1e-8 rad: a start one Newton step from the root.
    inverse: Option<Pieces>,
    /// Δ at the range's ends: what it is held at beyond them.
    held: (f64, f64),
}

/// Terms of each piece's Chebyshev series.
const TERMS: usize = 6;

/// A function on [lo, hi] as equal pieces, each a Chebyshev series of `TERMS` terms.
#[derive(Clone, Debug, PartialEq)]
struct Pieces {
    lo: f64,
    hi: f64,
    /// Pieces per unit of the argument.
    density: f64,
    c: Vec<[f64; TERMS]>,
}

impl Pieces {
    /// `n` pieces, each through `f` at its Chebyshev nodes.
    fn fit(lo: f64, hi: f64, n: usize, f: impl Fn(f64) -> f64) -> Pieces {
        use std::f64::consts::PI;
        let node = |j: usize| (PI * (j as f64 + 0.5) / TERMS as f64).cos();
        let width = (hi - lo) / n as f64;
        let c = (0..n)
            .map(|p| {
                let mid = lo + width * (p as f64 + 0.5);
                let values: [f64; TERMS] = std::array::from_fn(|j| f(mid + 0.5 * width * node(j)));
                std::array::from_fn(|k| {
                    let sum: f64 = (0..TERMS).map(|j| values[j] * (PI * k as f64 * (j as f64 + 0.5) / TERMS as f64).cos()).sum();
                    sum * if k == 0 { 1.0 } else { 2.0 } / TERMS as f64
                })
            })
            .collect();
        Pieces { lo, hi, density: n as f64 / (hi - lo), c }
    }

    /// The piece's series at `x` in [lo, hi], by Clenshaw's recurrence.
    #[inline]
    fn eval(&self, x: f64) -> f64 {
        let u = (x - self.lo) * self.density;
        let p = (u as usize).min(self.c.len() - 1);
        let t = 2.0 * (u - p as f64) - 1.0;
        let c = &self.c[p];
        let (mut b1, mut b2) = (0.0, 0.0);
        for &ck in c[1..].iter().rev() {
            (b1, b2) = (2.0 * t * b1 - b2 + ck, b1);
        }
        t * b1 - b2 + c[0]
    }
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
            max_curve: 0.0,
            inverse: None,
            held: (0.0, 0.0),
        };
        e.held = (e.delta(e.range.0), e.delta(e.range.1));
        let r = e.range.0.abs().max(e.range.1.abs());
        e.max_curve = (2..e.k.len()).map(|i| (i * (i - 1)) as f64 * e.k[i].abs() * r.powi(i as i32 - 2)).sum();
        e.max_abs = (0..=1000)
            .map(|i| e.poly(e.range.0 + (e.range.1 - e.range.0) * i as f64 / 1000.0).abs())
            .fold(0.0, f64::max);
        e.inverse = e.fit_inverse();
        e
    }

    /// The inverse over the range in the fewest pieces (8 to 512) that keep it within 1e-8 rad
    /// (checked between the nodes); `None` where none does.
    fn fit_inverse(&self) -> Option<Pieces> {
        let (r0, r1) = self.range;
        let (lo, hi) = (r0 + self.held.0, r1 + self.held.1);
        if !(lo < hi) {
            return None;
        }
        let exact = |a: f64| self.solve_from(a, a - self.delta(a));
        [8, 16, 32, 64, 128, 256, 512].into_iter().find_map(|n| {
            let fit = Pieces::fit(lo, hi, n, exact);
            let worst = (0..8 * n)
                .map(|i| {
                    let a = lo + (hi - lo) * (i as f64 + 0.5) / (8 * n) as f64;
                    (fit.eval(a) - exact(a)).abs()
                })
                .fold(0.0, f64::max);
            (worst <= 1e-8).then_some(fit)
        })
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
            let (_, slope) = self.value_and_slope(x);
            if slope <= 0.05 {
                return Err(format!(
                    "c + Δ(c) must increase over the fitted range; its slope is {slope:.3} at {:.3}°",
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

    /// Δ(word) in radians, with the word clamped into the fitted range.
    #[inline]
    pub fn delta(&self, word: f64) -> f64 {
        self.poly(word.clamp(self.range.0, self.range.1))
    }

    pub fn in_range(&self, word: f64) -> bool {
        word >= self.range.0 - 1e-12 && word <= self.range.1 + 1e-12
    }

    /// Δ and `1 + Δ'` (the slope of `c + Δ(c)`, 1 outside the range where Δ is held) at `c`,
    /// by one Horner pass.
    #[inline]
    fn value_and_slope(&self, c: f64) -> (f64, f64) {
        let x = c.clamp(self.range.0, self.range.1);
        let (mut p, mut dp) = (0.0, 0.0);
        for &k in self.k.iter().rev() {
            dp = dp * x + p;
            p = p * x + k;
        }
        (p, if self.in_range(c) { 1.0 + dp } else { 1.0 })
    }

    /// The word `c` with `c + Δ(c) = actual`: from the inverse's series within the range's image
    /// (one Newton step from the root), exact beyond it.
    pub fn word_for(&self, actual: f64) -> f64 {
        match &self.inverse {
            Some(f) if actual >= f.lo && actual <= f.hi => self.solve_from(actual, f.eval(actual)),
            // Beyond the range's image the word is beyond the range, where Δ is held.
            Some(f) if actual < f.lo => actual - self.held.0,
            Some(f) if actual > f.hi => actual - self.held.1,
            _ => self.solve_from(actual, actual - self.delta(actual)),
        }
    }

    /// [`AngleError::word_for`] from the start `c`: safeguarded Newton inside a bracket that must
    /// hold the root, because `c + Δ(c)` is strictly increasing (checked by `validate`). A step
    /// taken where Δ is one polynomial (or held) on both its ends lands within `max_curve·step²/2`
    /// of the root: once that is below the residual's own rounding, no evaluation confirms it.
    fn solve_from(&self, actual: f64, c: f64) -> f64 {
        let (mut lo, mut hi) = (actual - self.max_abs - 1e-9, actual + self.max_abs + 1e-9);
        let mut c = c;
        // The rounding of the residual itself: below it only the last bits would be chased.
        let floor = 4.0 * f64::EPSILON * (1.0 + actual.abs());
        // Where Δ is held (0, 2) or one polynomial (1); 3: the slivers `in_range` admits
        // beyond the range, where the slope it gives is not Δ's.
        let (r0, r1) = self.range;
        let side = |x: f64| match x {
            x if x < r0 - 1e-12 => 0,
            x if x > r1 + 1e-12 => 2,
            x if x >= r0 && x <= r1 => 1,
            _ => 3,
        };
        for _ in 0..100 {
            let (d, slope) = self.value_and_slope(c);
            let v = c + d - actual;
            if v.abs() <= floor {
                return c;
            }
            if v < 0.0 {
                lo = c;
            } else {
                hi = c;
            }
            let step = v / slope;
            let mut next = c - step;
            if !(next > lo && next < hi) {
                next = 0.5 * (lo + hi);
            } else if side(c) == side(next) && side(c) != 3 && 0.5 * self.max_curve * step * step <= floor {
                return next;
            }
            if (next - c).abs() <= 1e-16 * (1.0 + c.abs()) || hi - lo <= 1e-16 * (1.0 + c.abs()) {
                return next;
            }
            c = next;
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::AngleError;

    /// The word's residual `c + Δ(c) − actual` stays at rounding level wherever the actual
    /// angle lies: inside the fitted range, on its edges, in the slivers past them and beyond,
    /// for the paper's polynomial and for steeper ones, with the inverse's pieces and without.
    #[test]
    fn the_word_reproduces_the_actual_angle_to_rounding_everywhere() {
        let errors = [
            AngleError::new(vec![0.1808, -2.95e-2, 2.3e-3, -7e-5, -8e-7], (0.0, 40.0)),
            AngleError::new(vec![0.0, 0.4, 0.0, -1e-5], (-90.0, 90.0)),
            AngleError::new(vec![2.0, -0.5, 8e-3, 1e-4, -2e-6, 1e-8], (-30.0, 60.0)),
        ];
        for e in &errors {
            assert!(e.validate().is_ok());
            assert!(e.inverse.is_some(), "a smooth inverse has a short series");
            let (r0, r1) = e.range;
            let mut wanted: Vec<f64> = (0..20_011).map(|i| -3.5 + 7.0 * i as f64 / 20_011.0).collect();
            for edge in [r0, r1] {
                let at = edge + e.delta(edge);
                wanted.extend([-1e-9, -1e-12, -1e-13, 0.0, 1e-13, 1e-12, 1e-9].map(|d| at + d));
            }
            // And from the plain start, whose Newton steps end where the curvature still shows.
            let plain = AngleError { inverse: None, ..e.clone() };
            for (e, a) in [e, &plain].into_iter().flat_map(|e| wanted.iter().map(move |&a| (e, a))) {
                let c = e.word_for(a);
                let residual = c + e.delta(c) - a;
                assert!(
                    residual.abs() <= 16.0 * f64::EPSILON * (1.0 + a.abs()),
                    "actual {a}: word {c} leaves {residual:e}"
                );
            }
        }
    }
}
