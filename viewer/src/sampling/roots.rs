//! The first root of a cubic on `[0, 1]`: where `exact` finds the iso-surface inside one
//! interval between lattice planes ([`crate::reconstruct::Cubic`]).

use crate::reconstruct::Cubic;

/// First root of the cubic on `[0, 1]` (a sign change or an exact zero), refined by
/// bisection to round-off.
pub(crate) fn first_root(c: &Cubic) -> Option<f64> {
    // Bernstein coefficients on [0, 1]: g lies in their convex hull, so when all of them
    // are clearly of one sign g has no zero there (most intervals whose cells straddle
    // the iso value), without the critical points and evaluations below.
    let b = [
        c.c[0],
        c.c[0] + c.c[1] / 3.0,
        c.c[0] + (2.0 * c.c[1] + c.c[2]) / 3.0,
        c.c[0] + c.c[1] + c.c[2] + c.c[3],
    ];
    let margin = 1e-9 * (c.c[0].abs() + c.c[1].abs() + c.c[2].abs() + c.c[3].abs());
    if b.iter().all(|&x| x > margin) || b.iter().all(|&x| x < -margin) {
        return None;
    }
    // Where the weights vanish (outer support boundary) g is zero without a surface.
    let wscale = c.weight.iter().map(|x| x.abs()).sum::<f64>();
    let real_zero = |x: f64| c.weight_at(x) > 1e-7 * wscale;
    let mut g0 = c.eval(0.0);
    if g0 == 0.0 {
        if real_zero(0.0) {
            return Some(0.0);
        }
        g0 = c.eval(1e-9);
        if g0 == 0.0 {
            return None;
        }
    }
    // Monotone pieces between the critical points.
    let mut cuts = [0.0, 1.0, 1.0, 1.0];
    let mut n = 1;
    let (qa, qb, qc) = (3.0 * c.c[3], 2.0 * c.c[2], c.c[1]);
    let scale = qa.abs() + qb.abs() + qc.abs();
    let mut roots = [f64::NAN; 2];
    if qa.abs() <= 1e-14 * scale {
        if qb != 0.0 {
            roots[0] = -qc / qb;
        }
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let q = -0.5 * (qb + qb.signum() * disc.sqrt());
            roots[0] = q / qa;
            if q != 0.0 {
                roots[1] = qc / q;
            }
        }
    }
    if roots[0] > roots[1] {
        roots.swap(0, 1);
    }
    for x in roots {
        if x > 0.0 && x < 1.0 {
            cuts[n] = x;
            n += 1;
        }
    }
    cuts[n] = 1.0;
    let mut xa = 0.0;
    let mut ga = g0;
    for &xb in &cuts[1..=n] {
        if xb <= xa {
            continue;
        }
        let gb = c.eval(xb);
        if gb == 0.0 {
            if real_zero(xb) {
                return Some(xb);
            }
            xa = xb;
            continue;
        }
        if (ga < 0.0) != (gb < 0.0) {
            // g is monotone on [xa, xb]: Newton steps kept inside the shrinking bracket
            // (bisection where a step would leave it), to round-off.
            let (mut lo, mut hi) = (xa, xb);
            let mut x = 0.5 * (lo + hi);
            for _ in 0..100 {
                let gm = c.eval(x);
                if gm == 0.0 {
                    if real_zero(x) {
                        return Some(x);
                    }
                    break;
                }
                if (gm < 0.0) == (ga < 0.0) {
                    lo = x;
                } else {
                    hi = x;
                }
                let dg = c.slope(x);
                let newton = x - gm / dg;
                let next = if newton > lo && newton < hi {
                    newton
                } else {
                    0.5 * (lo + hi)
                };
                if next <= lo || next >= hi || (next - x).abs() <= 4.0 * f64::EPSILON {
                    x = next.clamp(lo, hi);
                    break;
                }
                x = next;
            }
            if real_zero(x) {
                return Some(x);
            }
        }
        xa = xb;
        ga = gb;
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cubic_from_roots(r: [f64; 3], scale: f64) -> Cubic {
        // scale·(x − r0)(x − r1)(x − r2), weights constant 1.
        let [a, b, c] = r;
        Cubic {
            c: [
                -scale * a * b * c,
                scale * (a * b + a * c + b * c),
                -scale * (a + b + c),
                scale,
            ],
            weight: [1.0, 0.0, 0.0, 0.0],
            any_above: true,
            any_below: true,
        }
    }

    #[test]
    fn first_root_of_cubics() {
        for (roots, want) in [
            ([0.3, 0.5, 0.9], Some(0.3)),
            ([-1.0, 0.7, 2.0], Some(0.7)),
            ([-1.0, 1.5, 2.0], None),
            ([0.25, 0.2500001, 3.0], Some(0.25)), // two close roots: the first
        ] {
            for scale in [1.0, -3.0, 1e-6] {
                let got = first_root(&cubic_from_roots(roots, scale));
                match (got, want) {
                    (Some(g), Some(w)) => assert!((g - w).abs() < 1e-9, "{roots:?}: {g} vs {w}"),
                    (None, None) => {}
                    _ => panic!("{roots:?} scale {scale}: got {got:?}, want {want:?}"),
                }
            }
        }
        // A zero where the weights vanish (outer support boundary) is not a surface.
        let mut c = cubic_from_roots([0.0, 5.0, 6.0], 1.0);
        c.weight = [0.0, 1.0, 0.0, 0.0];
        assert_eq!(first_root(&c), None);
    }
}
