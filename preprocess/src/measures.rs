//! Vortex measures of a velocity gradient `g[i][j] = ∂uᵢ/∂xⱼ`: Q, λ2, the vorticity and the
//! normalised helicity.
//!
//! The bake evaluates them on the gradient of [`crate::derive::gradient`] (one stencil for
//! all of them, so they are exactly as accurate as each other), and the lab on the closed
//! form gradients of its analytic flows, so that a baked value and its exact counterpart
//! always come from the same formula.
//!
//! With `S = ½(g + gᵀ)` and `Ω = ½(g − gᵀ)` the strain-rate and rotation-rate tensors:
//! - `Q = ½(‖Ω‖² − ‖S‖²)`: positive where rotation dominates strain ([`q`]);
//! - `λ2`: the middle eigenvalue of the symmetric `S² + Ω² = ½(g² + gᵀ²)`, negative in
//!   vortex cores ([`lambda2`], with the eigenvalues from [`symmetric_eigenvalues`]);
//! - `ω = ∇ × u` and its magnitude ([`vorticity`], [`vorticity_magnitude`]);
//! - `u · ω / (|u| |ω|)` in [−1, 1], zero where either vector is ([`helicity`]).

// Tensor formulas read best with explicit indices.
#![allow(clippy::needless_range_loop)]

/// Velocity gradient `g[i][j] = ∂uᵢ/∂xⱼ`.
pub type Gradient = [[f64; 3]; 3];

/// `Q = ½(‖Ω‖² − ‖S‖²) = −½ Σᵢⱼ gᵢⱼ gⱼᵢ`.
pub fn q(g: &Gradient) -> f64 {
    let mut s = 0.0;
    for (i, row) in g.iter().enumerate() {
        for (j, gij) in row.iter().enumerate() {
            s += gij * g[j][i];
        }
    }
    // `+ 0.0` turns −0 (zero gradient) into +0 so that ranges print as 0.
    -0.5 * s + 0.0
}

/// Vorticity `ω = ∇ × u = (∂u_z/∂y − ∂u_y/∂z, ∂u_x/∂z − ∂u_z/∂x, ∂u_y/∂x − ∂u_x/∂y)`.
pub fn vorticity(g: &Gradient) -> [f64; 3] {
    [g[2][1] - g[1][2], g[0][2] - g[2][0], g[1][0] - g[0][1]]
}

/// `|ω|`, without overflow or underflow in the squares.
pub fn vorticity_magnitude(g: &Gradient) -> f64 {
    norm(vorticity(g))
}

/// λ2: the middle eigenvalue of `S² + Ω²`, negative in vortex cores (Jeong and Hussain's
/// criterion). Zero for a zero gradient; `−Q` for any flow in a plane (there `S² + Ω²`
/// has the eigenvalues `−Q`, `−Q` and 0).
pub fn lambda2(g: &Gradient) -> f64 {
    // S² + Ω² = ½(g g + gᵀ gᵀ): (g g)ᵢⱼ = Σₖ gᵢₖ gₖⱼ and (gᵀ gᵀ)ᵢⱼ = (g g)ⱼᵢ.
    let mut gg = [[0.0; 3]; 3];
    for (i, row) in gg.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| g[i][k] * g[k][j]).sum();
        }
    }
    let mut m = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = 0.5 * (gg[i][j] + gg[j][i]);
        }
    }
    symmetric_eigenvalues(&m)[1] + 0.0
}

/// Eigenvalues of the symmetric matrix `m` (only its upper triangle is read), ascending.
///
/// Closed form: with `q = tr m / 3` and `p² = ‖m − q I‖² / 6`, the matrix
/// `B = (m − q I) / p` has the eigenvalues `2 cos(φ + 2πk/3)` where `cos 3φ = det B / 2`.
/// The matrix is scaled by its largest entry first (no overflow or underflow in `p²` or
/// the determinant), a diagonal matrix (which includes zero and `c I`) is sorted as it
/// is, and `det B / 2` is clamped to [−1, 1] where rounding takes it past, so repeated
/// eigenvalues give no NaN. Non-finite entries give NaN eigenvalues.
pub fn symmetric_eigenvalues(m: &[[f64; 3]; 3]) -> [f64; 3] {
    let entries = [m[0][0], m[1][1], m[2][2], m[0][1], m[0][2], m[1][2]];
    if !entries.iter().all(|v| v.is_finite()) {
        return [f64::NAN; 3];
    }
    let scale = entries.iter().fold(0.0f64, |s, v| s.max(v.abs()));
    if scale == 0.0 {
        return [0.0; 3];
    }
    let a = |i: usize, j: usize| m[i.min(j)][i.max(j)] / scale;
    let off = a(0, 1) * a(0, 1) + a(0, 2) * a(0, 2) + a(1, 2) * a(1, 2);
    let mut e = if off == 0.0 {
        [a(0, 0), a(1, 1), a(2, 2)]
    } else {
        let q = (a(0, 0) + a(1, 1) + a(2, 2)) / 3.0;
        let d = [a(0, 0) - q, a(1, 1) - q, a(2, 2) - q];
        let p = ((d[0] * d[0] + d[1] * d[1] + d[2] * d[2] + 2.0 * off) / 6.0).sqrt();
        // B = (m − q I) / p; r = det B / 2.
        let b = |i: usize, j: usize| if i == j { d[i] / p } else { a(i, j) / p };
        let det = b(0, 0) * (b(1, 1) * b(2, 2) - b(1, 2) * b(1, 2))
            - b(0, 1) * (b(0, 1) * b(2, 2) - b(1, 2) * b(0, 2))
            + b(0, 2) * (b(0, 1) * b(1, 2) - b(1, 1) * b(0, 2));
        let phi = (0.5 * det).clamp(-1.0, 1.0).acos() / 3.0;
        let largest = q + 2.0 * p * phi.cos();
        let smallest = q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos();
        // The trace gives the third; it lies between the two up to rounding.
        [smallest, 3.0 * q - largest - smallest, largest]
    };
    e.sort_by(f64::total_cmp);
    e.map(|v| v * scale)
}

/// Normalised helicity `u · ω / (|u| |ω|)` of the velocity `u` with gradient `g`: the
/// cosine of the angle between velocity and vorticity, in [−1, 1]; 0 where `u` or `ω` is
/// zero. Where `|ω|` is at the rounding level of the gradient (an irrotational flow) the
/// angle, and so the value, is as uncertain as `ω`'s direction.
pub fn helicity(u: &[f64; 3], g: &Gradient) -> f64 {
    let (Some(a), Some(b)) = (unit(*u), unit(vorticity(g))) else {
        return 0.0;
    };
    (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).clamp(-1.0, 1.0) + 0.0
}

/// Euclidean norm, scaled by the largest component so that neither tiny nor huge
/// components are lost in the squares.
fn norm(v: [f64; 3]) -> f64 {
    if !v.iter().all(|c| c.is_finite()) {
        // NaN for a NaN component (f64::max would skip it), else +∞.
        return v.iter().map(|c| c.abs()).sum();
    }
    let s = v.iter().fold(0.0f64, |s, c| s.max(c.abs()));
    if s == 0.0 {
        return s;
    }
    let w = v.map(|c| c / s);
    s * (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt()
}

/// `v / |v|`, `None` for a zero vector (NaN components for a non-finite one).
fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let n = norm(v);
    (n != 0.0).then(|| v.map(|c| c / n))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    /// `r m rᵀ` for the rotation `r` by `angle` about the (normalised) `axis`.
    fn rotated(m: &[[f64; 3]; 3], axis: [f64; 3], angle: f64) -> [[f64; 3]; 3] {
        let n = norm(axis);
        let [x, y, z] = axis.map(|c| c / n);
        let (s, c) = angle.sin_cos();
        let t = 1.0 - c;
        let r = [
            [t * x * x + c, t * x * y - s * z, t * x * z + s * y],
            [t * x * y + s * z, t * y * y + c, t * y * z - s * x],
            [t * x * z - s * y, t * y * z + s * x, t * z * z + c],
        ];
        let mut out = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    for l in 0..3 {
                        out[i][j] += r[i][k] * m[k][l] * r[j][l];
                    }
                }
            }
        }
        // Exactly symmetric, as S² + Ω² is.
        for i in 0..3 {
            for j in 0..i {
                let v = 0.5 * (out[i][j] + out[j][i]);
                out[i][j] = v;
                out[j][i] = v;
            }
        }
        out
    }

    fn diag(d: [f64; 3]) -> [[f64; 3]; 3] {
        [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]
    }

    #[test]
    fn eigenvalues_of_diagonal_zero_and_multiples_of_identity() {
        assert_eq!(symmetric_eigenvalues(&[[0.0; 3]; 3]), [0.0; 3]);
        assert_eq!(
            symmetric_eigenvalues(&diag([3.0, -1.0, 2.0])),
            [-1.0, 2.0, 3.0]
        );
        assert_eq!(symmetric_eigenvalues(&diag([2.5; 3])), [2.5; 3]);
        // Tiny and huge matrices keep their eigenvalues (the scaling).
        let e = symmetric_eigenvalues(&rotated(&diag([1e-300, -2e-300, 0.0]), [1.0; 3], 0.4));
        for (v, w) in e.iter().zip([-2e-300, 0.0, 1e-300]) {
            assert!((v - w).abs() < 1e-12 * 1e-300, "{e:?}");
        }
        let big = rotated(&diag([1e300, -1e300, 5e299]), [1.0, 2.0, 3.0], 0.7);
        let e = symmetric_eigenvalues(&big);
        for (v, w) in e.iter().zip([-1e300, 5e299, 1e300]) {
            assert!((v - w).abs() < 1e-12 * 1e300, "{e:?}");
        }
        assert!(symmetric_eigenvalues(&diag([f64::NAN, 0.0, 0.0]))
            .iter()
            .all(|v| v.is_nan()));
    }

    #[test]
    fn eigenvalues_of_rotated_matrices_with_repeated_values() {
        let cases = [
            [1.0, 2.0, 3.0],
            [-1.0, 2.0, 2.0],
            [-1.0, -1.0, 2.0],
            [4.0, 4.0, 4.0],
            [0.0, 0.0, 1e-9],
            [-0.49, -0.49, 0.0],
            [1.0, 1.0 + 1e-12, 5.0],
        ];
        for want in cases {
            for (axis, angle) in [
                ([1.0, 0.0, 0.0], 0.3),
                ([1.0, 2.0, 3.0], 1.1),
                ([-2.0, 0.5, 1.0], 2.9),
            ] {
                let m = rotated(&diag(want), axis, angle);
                let e = symmetric_eigenvalues(&m);
                assert!(e.iter().all(|v| v.is_finite()), "{want:?}: {e:?}");
                let scale = want.iter().fold(0.0f64, |s, v| s.max(v.abs()));
                for k in 0..3 {
                    // Repeated eigenvalues cost the closed form about √ε of the scale.
                    assert!(
                        (e[k] - want[k]).abs() <= 1e-7 * scale,
                        "{want:?} about {axis:?}: {e:?}"
                    );
                }
                assert!(e[0] <= e[1] && e[1] <= e[2], "{e:?}");
            }
        }
    }

    #[test]
    fn eigenvalues_of_random_symmetric_matrices_satisfy_the_invariants() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..200 {
            let (a, b, c, d, e, f) = (next(), next(), next(), next(), next(), next());
            let m = [[a, d, e], [d, b, f], [e, f, c]];
            let l = symmetric_eigenvalues(&m);
            let tr = a + b + c;
            let minors = a * b + b * c + a * c - d * d - e * e - f * f;
            let det = a * (b * c - f * f) - d * (d * c - f * e) + e * (d * f - b * e);
            assert!((l[0] + l[1] + l[2] - tr).abs() < 1e-12);
            assert!((l[0] * l[1] + l[1] * l[2] + l[0] * l[2] - minors).abs() < 1e-12);
            assert!((l[0] * l[1] * l[2] - det).abs() < 1e-12);
        }
    }

    #[test]
    fn lambda2_of_rotation_strain_and_a_burgers_core() {
        // Solid-body rotation u = (−w y, w x, 0): S = 0, Ω² = diag(−w², −w², 0).
        let w = 0.7;
        let rot = [[0.0, -w, 0.0], [w, 0.0, 0.0], [0.0, 0.0, 0.0]];
        assert!(close(lambda2(&rot), -w * w, 1e-15));
        assert!(close(q(&rot), w * w, 1e-15));
        // Pure strain u = (a x, −a y, 0): S² = diag(a², a², 0), λ2 = a² > 0.
        let a = 0.3;
        let strain = [[a, 0.0, 0.0], [0.0, -a, 0.0], [0.0, 0.0, 0.0]];
        assert!(close(lambda2(&strain), a * a, 1e-15));
        assert!(close(q(&strain), -a * a, 1e-15));
        // Axisymmetric strain (−α/2, −α/2, α): S² = diag(α²/4, α²/4, α²).
        let s = 0.2;
        let axi = diag([-0.5 * s, -0.5 * s, s]);
        assert!(close(lambda2(&axi), 0.25 * s * s, 1e-15));
        // Burgers vortex on its axis: rotation w about z plus that strain. S and Ω
        // commute there, S² + Ω² = diag(α²/4 − w², α²/4 − w², α²): λ2 = α²/4 − w².
        let core = [[-0.5 * s, -w, 0.0], [w, -0.5 * s, 0.0], [0.0, 0.0, s]];
        assert!(close(lambda2(&core), 0.25 * s * s - w * w, 1e-14));
        assert!(lambda2(&core) < 0.0);
        // Zero gradient: λ2 = +0, no NaN.
        let z = lambda2(&[[0.0; 3]; 3]);
        assert!(z == 0.0 && z.is_sign_positive());
        // Simple shear u = (k y, 0, 0): S² + Ω² = diag(0, 0, 0) up to the off terms,
        // which cancel; λ2 = 0 (neither vortex nor strain dominates).
        let shear = [[0.0, 0.4, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]];
        assert!(lambda2(&shear).abs() < 1e-15);
    }

    #[test]
    fn lambda2_is_minus_q_in_plane_flows() {
        let mut x = 7u64;
        let mut next = || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..100 {
            let (a, b, c) = (next(), next(), next());
            let g = [[a, b, 0.0], [c, -a, 0.0], [0.0, 0.0, 0.0]];
            assert!((lambda2(&g) + q(&g)).abs() < 1e-7, "{g:?}");
        }
    }

    #[test]
    fn vorticity_and_helicity() {
        let rot = [[0.0, -0.7, 0.0], [0.7, 0.0, 0.0], [0.0, 0.0, 0.0]];
        assert_eq!(vorticity(&rot), [0.0, 0.0, 1.4]);
        assert!(close(vorticity_magnitude(&rot), 1.4, 1e-15));
        // Velocity along the vorticity, against it, across it, or zero.
        assert!(close(helicity(&[0.0, 0.0, 2.0], &rot), 1.0, 1e-15));
        assert!(close(helicity(&[0.0, 0.0, -2.0], &rot), -1.0, 1e-15));
        assert_eq!(helicity(&[1.0, 0.0, 0.0], &rot), 0.0);
        assert_eq!(helicity(&[0.0; 3], &rot), 0.0);
        // Irrotational strain: no vorticity, helicity 0 (no NaN).
        let strain = [[0.3, 0.0, 0.0], [0.0, -0.3, 0.0], [0.0, 0.0, 0.0]];
        assert_eq!(vorticity_magnitude(&strain), 0.0);
        assert_eq!(helicity(&[1.0, 2.0, 3.0], &strain), 0.0);
        // Tiny vectors are not lost in the squares.
        let tiny = rot.map(|r| r.map(|v| v * 1e-200));
        assert!(close(helicity(&[0.0, 0.0, 1e-200], &tiny), 1.0, 1e-15));
        assert!(close(vorticity_magnitude(&tiny) * 1e200, 1.4, 1e-15));
        // Non-finite input stays visible (the bake counts it), never a finite lie.
        let nan = [[f64::NAN, 0.0, 0.0], [0.0; 3], [0.0; 3]];
        let inf = [[0.0, f64::INFINITY, 0.0], [0.0; 3], [0.0; 3]];
        assert!(lambda2(&nan).is_nan() && lambda2(&inf).is_nan());
        assert_eq!(vorticity_magnitude(&inf), f64::INFINITY);
        assert!(helicity(&[1.0, 0.0, 0.0], &inf).is_nan());
        // Helicity stays in [−1, 1] when rounding would take the cosine past.
        let g = [[0.0, -0.1, 0.2], [0.1, 0.0, -0.3], [-0.2, 0.3, 0.0]];
        let w = vorticity(&g);
        assert!(helicity(&w, &g) <= 1.0 && helicity(&w, &g) > 1.0 - 1e-15);
    }
}
