//! Small least-squares polynomial fits (no allocation): what the bounce
//! detector, the noise estimate and the baseline predictor share.

/// Least-squares polynomial of degree `N − 1` through `pts` = (τ, value):
/// returns `c` with value ≈ Σ c_k τ^k. The caller centres τ; internally τ is
/// scaled to [−1, 1] so the normal equations stay well conditioned. `None`
/// with fewer than `N` points or a singular system (e.g. repeated τ).
pub(crate) fn polyfit<const N: usize>(pts: &[(f64, f64)]) -> Option<[f64; N]> {
    if pts.len() < N || N == 0 {
        return None;
    }
    let scale = pts.iter().map(|p| p.0.abs()).fold(0.0, f64::max);
    if !(scale > 0.0 && scale.is_finite()) {
        return None;
    }
    // Normal equations in the scaled variable u = τ / scale.
    let mut a = [[0.0; N]; N];
    let mut b = [0.0; N];
    for &(tau, v) in pts {
        let u = tau / scale;
        let mut pow = [1.0; N];
        for k in 1..N {
            pow[k] = pow[k - 1] * u;
        }
        for i in 0..N {
            b[i] += pow[i] * v;
            for j in 0..N {
                a[i][j] += pow[i] * pow[j];
            }
        }
    }
    let mut c = solve(a, b)?;
    let mut s = 1.0;
    for ck in c.iter_mut() {
        *ck /= s;
        s *= scale;
    }
    Some(c)
}

/// Gaussian elimination with partial pivoting.
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let piv = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        let pivot_row = a[col];
        for row in col + 1..N {
            let f = a[row][col] / pivot_row[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *x -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let mut s = b[row];
        for k in row + 1..N {
            s -= a[row][k] * x[k];
        }
        x[row] = s / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Σ c_k τ^k.
pub(crate) fn eval<const N: usize>(c: &[f64; N], tau: f64) -> f64 {
    c.iter().rev().fold(0.0, |acc, &ck| acc * tau + ck)
}

/// d/dτ Σ c_k τ^k.
pub(crate) fn eval_deriv<const N: usize>(c: &[f64; N], tau: f64) -> f64 {
    (1..N).rev().fold(0.0, |acc, k| acc * tau + k as f64 * c[k])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_cubic() {
        let f = |t: f64| 1.0 - 2.0 * t + 0.5 * t * t + 3.0 * t * t * t;
        let pts: Vec<_> = (0..20)
            .map(|i| {
                let t = -0.2 + 0.02 * i as f64;
                (t, f(t))
            })
            .collect();
        let c = polyfit::<4>(&pts).unwrap();
        for (ck, want) in c.iter().zip([1.0, -2.0, 0.5, 3.0]) {
            assert!((ck - want).abs() < 1e-8, "{c:?}");
        }
        assert!((eval(&c, 0.1) - f(0.1)).abs() < 1e-12);
        assert!((eval_deriv(&c, 0.1) - (-2.0 + 0.1 + 9.0 * 0.01)).abs() < 1e-9);
    }

    #[test]
    fn too_few_or_degenerate_points_give_none() {
        assert!(polyfit::<3>(&[(0.0, 1.0), (1.0, 2.0)]).is_none());
        assert!(polyfit::<2>(&[(0.5, 1.0), (0.5, 2.0), (0.5, 3.0)]).is_none());
        assert!(polyfit::<2>(&[(0.0, 1.0), (0.0, 2.0)]).is_none());
    }
}
