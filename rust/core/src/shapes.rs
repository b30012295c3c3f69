//! The built-in obstacle shapes evaluated here, in the problem's units: quadratics (disks, ellipses,
//! half-planes: [`Quadratics`]) and rounded boxes. The obstacle occupies `phi >= 0`.
//!
//! A box: half sizes (hx, hy), corner radius r, turned by a rotation R (its columns the box's axes
//! in the plane). In the box's frame `q = R^T (p - c)`, phi is minus the signed distance to the
//! rounded rectangle: beyond both inner edges (`|q_i| - (h_i - r) > 0`) a disk of radius r around the
//! inner corner, elsewhere a half-plane behind the nearer edge (inside, the larger of the two
//! depths). C1 everywhere but on the inner medial axis (deep inside, where no node sits), C2 away
//! from the region boundaries.

use crate::network::{Interrupted, NodeField, Quadratics};

/// One built-in shape.
#[derive(Clone, Debug)]
pub enum Shape {
    /// Obstacle `j` of the quadratics.
    Quadratic(usize),
    Box {
        centre: [f64; 2],
        half_size: [f64; 2],
        radius: f64,
        /// Row by row.
        rotation: [f64; 4],
    },
}

impl Shape {
    /// phi at `point` (2-D), its gradient and Hessian (row by row) into `gradient` and `hessian`.
    pub fn evaluate(
        &self,
        quadratics: &Quadratics,
        point: &[f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> f64 {
        match self {
            Shape::Quadratic(j) => {
                hessian.copy_from_slice(&quadratics.hessians[j * 4..j * 4 + 4]);
                quadratics.value_and_gradient(*j, 2, point, gradient)
            }
            Shape::Box {
                centre,
                half_size,
                radius,
                rotation: m,
            } => {
                let offset = [point[0] - centre[0], point[1] - centre[1]];
                // q = offset R (as a row vector)
                let q = [
                    offset[0] * m[0] + offset[1] * m[2],
                    offset[0] * m[1] + offset[1] * m[3],
                ];
                let sign = q.map(|v| if v >= 0.0 { 1.0 } else { -1.0 }); // 0 keeps its gradient on an axis
                let d = [
                    q[0].abs() - (half_size[0] - radius),
                    q[1].abs() - (half_size[1] - radius),
                ];
                let (phi, local_gradient, local_hessian) = if d[0] > 0.0 && d[1] > 0.0 {
                    let distance = (d[0] * d[0] + d[1] * d[1]).sqrt();
                    let unit = [sign[0] * d[0] / distance, sign[1] * d[1] / distance];
                    let mut h = [0.0; 4];
                    for i in 0..2 {
                        for k in 0..2 {
                            let identity = if i == k { 1.0 } else { 0.0 };
                            h[i * 2 + k] = -(identity - unit[i] * unit[k]) / distance;
                        }
                    }
                    (radius - distance, [-unit[0], -unit[1]], h)
                } else {
                    // a half-plane behind the nearer edge, its outward normal along that axis
                    let axis = if d[0] >= d[1] { [1.0, 0.0] } else { [0.0, 1.0] };
                    (
                        radius - d[0].max(d[1]),
                        [-sign[0] * axis[0], -sign[1] * axis[1]],
                        [0.0; 4],
                    )
                };
                // back to the plane: gradient R g, Hessian R H R^T
                gradient[0] = local_gradient[0] * m[0] + local_gradient[1] * m[1];
                gradient[1] = local_gradient[0] * m[2] + local_gradient[1] * m[3];
                let mut rh = [0.0; 4];
                for i in 0..2 {
                    for k in 0..2 {
                        rh[i * 2 + k] = m[i * 2] * local_hessian[k] + m[i * 2 + 1] * local_hessian[2 + k];
                    }
                }
                for i in 0..2 {
                    for k in 0..2 {
                        hessian[i * 2 + k] = rh[i * 2] * m[k * 2] + rh[i * 2 + 1] * m[k * 2 + 1];
                    }
                }
                phi
            }
        }
    }
}

/// Built-in shapes as a node field: every shape's phi, gradient and Hessian at every point.
pub struct NativeField {
    pub shapes: Vec<Shape>,
    pub quadratics: Quadratics,
}

impl NodeField for NativeField {
    fn count(&self) -> usize {
        self.shapes.len()
    }

    fn evaluate(
        &mut self,
        points: &[f64],
        phi: &mut [f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> Result<(), Interrupted> {
        let n = points.len() / 2;
        for (j, shape) in self.shapes.iter().enumerate() {
            for (i, point) in points.chunks_exact(2).enumerate() {
                let at = j * n + i;
                phi[at] = shape.evaluate(
                    &self.quadratics,
                    point,
                    &mut gradient[at * 2..at * 2 + 2],
                    &mut hessian[at * 4..at * 4 + 4],
                );
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box of half sizes (2, 1), corner radius 0.5, turned 90 degrees (its x axis along the plane's
    /// y): phi is minus the signed distance to its outline, by hand.
    #[test]
    fn a_turned_rounded_box_is_minus_the_signed_distance_to_its_outline() {
        let shape = Shape::Box {
            centre: [1.0, 0.0],
            half_size: [2.0, 1.0],
            radius: 0.5,
            rotation: [0.0, -1.0, 1.0, 0.0], // columns: the box's axes (0, 1) and (-1, 0)
        };
        let quadratics = Quadratics::default();
        let (mut g, mut h) = ([0.0; 2], [0.0; 4]);
        // 0.5 beyond the long side (the plane's x = 2): phi = -0.5, its gradient pointing in (-1, 0)
        let phi = shape.evaluate(&quadratics, &[2.5, 0.0], &mut g, &mut h);
        assert!((phi + 0.5).abs() < 1e-15 && (g[0] + 1.0).abs() < 1e-15 && g[1].abs() < 1e-15);
        assert_eq!(h, [0.0; 4]);
        // inside, 0.25 from the short side (the plane's y = 2): phi = 0.25, its gradient pointing in
        let phi = shape.evaluate(&quadratics, &[1.0, 1.75], &mut g, &mut h);
        assert!((phi - 0.25).abs() < 1e-15 && g[0].abs() < 1e-15 && (g[1] + 1.0).abs() < 1e-15);
        // beyond the corner: the inner corner at (1 + 0.5, 1.5), 1 away diagonally: phi = 0.5 - 1
        let s = 1.0 / 2f64.sqrt();
        let phi = shape.evaluate(&quadratics, &[1.5 + s, 1.5 + s], &mut g, &mut h);
        assert!((phi + 0.5).abs() < 1e-14, "{phi}");
        assert!((g[0] + s).abs() < 1e-14 && (g[1] + s).abs() < 1e-14);
        // the corner's curvature: -(I - u u^T) / distance with u = (s, s)
        let expected = [-0.5, 0.5, 0.5, -0.5];
        assert!(
            h.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-14),
            "{h:?}"
        );
    }
}
