//! Derivative-free minimisation (argmin's Nelder–Mead) of a cost over a few
//! parameters, with one restart from the optimum, Brent's method (argmin's)
//! over one bounded parameter, plus a numerical Hessian.

use argmin::core::{CostFunction, Error, Executor, State};
use argmin::solver::brent::BrentOpt;
use argmin::solver::neldermead::NelderMead;

/// A cost returned where a parameter vector is outside its domain.
pub const INVALID: f64 = 1e300;

struct Problem<'a, F>(&'a F);

impl<F: Fn(&[f64]) -> f64> CostFunction for Problem<'_, F> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, p: &Self::Param) -> Result<f64, Error> {
        let c = (self.0)(p);
        Ok(if c.is_finite() { c } else { INVALID })
    }
}

/// Result of [`minimize`].
#[derive(Debug, Clone, PartialEq)]
pub struct Minimum {
    /// Best parameters found.
    pub x: Vec<f64>,
    /// Cost at `x`.
    pub cost: f64,
}

fn run<F: Fn(&[f64]) -> f64>(f: &F, x0: &[f64], steps: &[f64], max_iters: u64) -> Minimum {
    let mut simplex = vec![x0.to_vec()];
    for (i, s) in steps.iter().enumerate() {
        let mut x = x0.to_vec();
        x[i] += s;
        simplex.push(x);
    }
    let fallback = Minimum {
        x: x0.to_vec(),
        cost: f(x0),
    };
    let Ok(solver) = NelderMead::new(simplex).with_sd_tolerance(1e-11) else {
        return fallback;
    };
    match Executor::new(Problem(f), solver)
        .configure(|s| s.max_iters(max_iters))
        .run()
    {
        Ok(res) => {
            let st = res.state();
            match st.get_best_param() {
                Some(x) if st.get_best_cost() <= fallback.cost => Minimum {
                    x: x.clone(),
                    cost: st.get_best_cost(),
                },
                _ => fallback,
            }
        }
        Err(_) => fallback,
    }
}

/// Minimises `f` from `x0` with Nelder–Mead (initial simplex `x0 + steps[i]·eᵢ`),
/// then restarts once from the optimum with half the steps, which guards
/// against a collapsed simplex. Deterministic.
pub fn minimize<F: Fn(&[f64]) -> f64>(f: &F, x0: &[f64], steps: &[f64]) -> Minimum {
    let iters = 400 * (x0.len() as u64 + 1);
    let first = run(f, x0, steps, iters);
    let half: Vec<f64> = steps.iter().map(|s| s * 0.5).collect();
    let second = run(f, &first.x, &half, iters);
    if second.cost <= first.cost {
        second
    } else {
        first
    }
}

struct Scalar<'a, F>(&'a F);

impl<F: Fn(f64) -> f64> CostFunction for Scalar<'_, F> {
    type Param = f64;
    type Output = f64;
    fn cost(&self, x: &f64) -> Result<f64, Error> {
        let c = (self.0)(*x);
        Ok(if c.is_finite() { c } else { INVALID })
    }
}

/// Minimises a unimodal `f` over `[lo, hi]` by Brent's method (argmin's
/// `BrentOpt`: parabolic steps through the three best points, a
/// golden-section step where a parabola would leave the bracket or stall);
/// the result is within about `tol + 3e−8·|x|` of the minimum, which may
/// lie at either end of the bracket. A non-finite cost counts as
/// `INVALID` (1e300). Returns the best point evaluated, `None` when the search
/// could not run. Deterministic.
///
/// Every cost here is a pass over many units or a whole survival fit, so
/// the parabolic steps matter: on smooth costs they reach the tolerance in
/// a third to a half of the evaluations golden-section steps alone need.
pub fn minimize_scalar<F: Fn(f64) -> f64>(f: &F, lo: f64, hi: f64, tol: f64) -> Option<f64> {
    if !(lo < hi && tol > 0.0) {
        return None;
    }
    let solver = BrentOpt::new(lo, hi).set_tolerance(f64::EPSILON.sqrt(), 0.5 * tol);
    let res = Executor::new(Scalar(f), solver)
        .configure(|s| s.max_iters(200))
        .run()
        .ok()?;
    res.state().get_best_param().copied()
}

/// Central-difference Hessian of `f` at `x` with steps `h`.
pub fn hessian<F: Fn(&[f64]) -> f64>(f: &F, x: &[f64], h: &[f64]) -> Vec<Vec<f64>> {
    let n = x.len();
    let f0 = f(x);
    let mut out = vec![vec![0.0; n]; n];
    let at = |d: &[(usize, f64)]| {
        let mut y = x.to_vec();
        for &(i, s) in d {
            y[i] += s;
        }
        f(&y)
    };
    for i in 0..n {
        let fp = at(&[(i, h[i])]);
        let fm = at(&[(i, -h[i])]);
        out[i][i] = (fp - 2.0 * f0 + fm) / (h[i] * h[i]);
        for j in 0..i {
            let v = (at(&[(i, h[i]), (j, h[j])])
                - at(&[(i, h[i]), (j, -h[j])])
                - at(&[(i, -h[i]), (j, h[j])])
                + at(&[(i, -h[i]), (j, -h[j])]))
                / (4.0 * h[i] * h[j]);
            out[i][j] = v;
            out[j][i] = v;
        }
    }
    out
}

/// Inverse of a small square matrix by Gauss–Jordan elimination with partial
/// pivoting; `None` when singular. Hand-written: the chosen linear-algebra
/// stack (ndarray without a LAPACK backend) has no general inverse, and the
/// matrices here are at most a dozen rows.
pub fn invert(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let mut m: Vec<Vec<f64>> = a
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let mut r = row.clone();
            r.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if !(m[piv][col].abs() > 1e-300) || !m[piv][col].is_finite() {
            return None;
        }
        m.swap(col, piv);
        let p = m[col][col];
        for v in &mut m[col] {
            *v /= p;
        }
        for r in 0..n {
            if r != col {
                let factor = m[r][col];
                if factor != 0.0 {
                    let pivot = m[col].clone();
                    for (x, p) in m[r].iter_mut().zip(&pivot) {
                        *x -= factor * p;
                    }
                }
            }
        }
    }
    Some(m.into_iter().map(|r| r[n..].to_vec()).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_minimum_of_a_shifted_quadratic() {
        let f = |p: &[f64]| (p[0] - 3.0).powi(2) + 10.0 * (p[1] + 1.5).powi(2) + 2.0;
        let m = minimize(&f, &[0.0, 0.0], &[1.0, 1.0]);
        assert!((m.x[0] - 3.0).abs() < 1e-5, "{:?}", m.x);
        assert!((m.x[1] + 1.5).abs() < 1e-5, "{:?}", m.x);
        assert!((m.cost - 2.0).abs() < 1e-9);
    }

    #[test]
    fn rosenbrock_converges() {
        let f = |p: &[f64]| (1.0 - p[0]).powi(2) + 100.0 * (p[1] - p[0] * p[0]).powi(2);
        let m = minimize(&f, &[-1.2, 1.0], &[0.5, 0.5]);
        assert!(
            (m.x[0] - 1.0).abs() < 1e-3 && (m.x[1] - 1.0).abs() < 2e-3,
            "{:?}",
            m.x
        );
    }

    #[test]
    fn hessian_and_inverse_of_a_quadratic_form() {
        // f = ½ xᵀ A x with A = [[4, 1], [1, 3]]: H = A, A⁻¹ = [[3, −1], [−1, 4]]/11.
        let f = |p: &[f64]| 0.5 * (4.0 * p[0] * p[0] + 2.0 * p[0] * p[1] + 3.0 * p[1] * p[1]);
        let h = hessian(&f, &[0.3, -0.2], &[1e-3, 1e-3]);
        assert!((h[0][0] - 4.0).abs() < 1e-6 && (h[0][1] - 1.0).abs() < 1e-6);
        let inv = invert(&h).unwrap();
        assert!((inv[0][0] - 3.0 / 11.0).abs() < 1e-6);
        assert!((inv[0][1] + 1.0 / 11.0).abs() < 1e-6);
        assert!(invert(&[vec![1.0, 2.0], vec![2.0, 4.0]]).is_none());
    }

    #[test]
    fn minimize_scalar_finds_minima_inside_and_at_the_bracket() {
        // A parabola, a non-parabolic smooth minimum, a minimum at either
        // end of the bracket (a monotone cost) and a cost infinite on part
        // of the bracket.
        let tol = 1e-7;
        let at = |f: &dyn Fn(f64) -> f64, lo, hi| minimize_scalar(&f, lo, hi, tol).unwrap();
        let x = at(&|x| (x - 0.7).powi(2), -2.0, 3.0);
        assert!((x - 0.7).abs() < 1e-6, "{x}");
        let x = at(&|x| (x - 1.3).abs().powf(1.5) + x.cosh() * 1e-3, -2.0, 3.0);
        assert!((x - 1.3).abs() < 1e-3, "{x}");
        let x = at(&|x| x, 0.0, 0.5);
        assert!(x < 1e-6, "{x}");
        let x = at(&|x| -x, 0.0, 0.5);
        assert!(x > 0.5 - 1e-6, "{x}");
        let x = at(
            &|x| {
                if x < 0.2 {
                    f64::INFINITY
                } else {
                    (x - 0.3).powi(2)
                }
            },
            0.0,
            1.0,
        );
        assert!((x - 0.3).abs() < 1e-6, "{x}");
        // A coarse tolerance stops early but stays within it.
        let x = minimize_scalar(&|x: f64| (x - 0.9).powi(4), 0.2, 1.8, 0.002).unwrap();
        assert!((x - 0.9).abs() < 0.002, "{x}");
        assert!(minimize_scalar(&|x: f64| x, 1.0, 1.0, tol).is_none());
    }
}
