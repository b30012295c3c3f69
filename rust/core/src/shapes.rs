//! The built-in obstacle shapes evaluated here, in the problem's units: quadratics (disks, ellipses,
//! half-planes, spheres, ellipsoids, half-spaces: [`Quadratics`]) and rounded boxes. The obstacle occupies `phi >= 0`.
//!
//! A box: half sizes h, corner radius r, turned by a rotation R (its columns the box's axes). In
//! the box's frame `q = R^T (p - c)`, phi is minus the signed distance to the rounded box: beyond
//! two or more inner faces (`|q_i| - (h_i - r) > 0`) a disk (in space: a cylinder along an edge, a
//! ball at a corner) of radius r around the inner corner or edge, elsewhere a half-plane behind the
//! nearest face (inside, the largest of the depths). C1 everywhere but on the inner medial axis (deep inside, where no node sits), C2 away
//! from the region boundaries.

use crate::problem::{Interrupted, NodeField, Quadratics};

/// One built-in shape.
#[derive(Clone, Debug)]
pub enum Shape {
    /// Obstacle `j` of the quadratics.
    Quadratic(usize),
    /// A rounded box in the plane (d = 2) or in space (d = 3): the first d entries of each array
    /// (the rotation: d x d, row by row).
    Box {
        centre: [f64; 3],
        half_size: [f64; 3],
        radius: f64,
        rotation: [f64; 9],
    },
}

impl Shape {
    /// A box in the plane from its parameters (see [`Shape::Box`]).
    pub fn plane_box(centre: [f64; 2], half_size: [f64; 2], radius: f64, rotation: [f64; 4]) -> Shape {
        Shape::Box {
            centre: [centre[0], centre[1], 0.0],
            half_size: [half_size[0], half_size[1], 0.0],
            radius,
            rotation: [
                rotation[0],
                rotation[1],
                rotation[2],
                rotation[3],
                0.0,
                0.0,
                0.0,
                0.0,
                0.0,
            ],
        }
    }

    /// phi at `point` (d coordinates), its gradient and Hessian (row by row) into `gradient` and
    /// `hessian`.
    pub fn evaluate(
        &self,
        quadratics: &Quadratics,
        point: &[f64],
        gradient: &mut [f64],
        hessian: &mut [f64],
    ) -> f64 {
        let d = point.len();
        match self {
            Shape::Quadratic(j) => {
                hessian.copy_from_slice(&quadratics.hessians[j * d * d..(j + 1) * d * d]);
                quadratics.value_and_gradient(*j, d, point, gradient)
            }
            Shape::Box {
                centre,
                half_size,
                radius,
                rotation: m,
            } => {
                // q = offset R (as a row vector): the point in the box's frame
                let mut q = [0.0; 3];
                for k in 0..d {
                    for i in 0..d {
                        q[k] += (point[i] - centre[i]) * m[i * d + k];
                    }
                }
                let mut sign = [0.0; 3];
                let mut depth = [0.0; 3];
                for i in 0..d {
                    sign[i] = if q[i] >= 0.0 { 1.0 } else { -1.0 }; // 0 keeps its gradient on an axis
                    depth[i] = q[i].abs() - (half_size[i] - radius);
                }
                let beyond: Vec<usize> = (0..d).filter(|&i| depth[i] > 0.0).collect();
                let mut local_gradient = [0.0; 3];
                let mut local_hessian = [0.0; 9];
                let phi = if beyond.len() >= 2 {
                    // beyond two or three inner faces: a disk (cylinder, ball) of radius r around
                    // the inner corner (edge)
                    let distance = beyond.iter().map(|&i| depth[i] * depth[i]).sum::<f64>().sqrt();
                    let mut unit = [0.0; 3];
                    for &i in &beyond {
                        unit[i] = sign[i] * depth[i] / distance;
                        local_gradient[i] = -unit[i];
                    }
                    for &i in &beyond {
                        for &k in &beyond {
                            let identity = if i == k { 1.0 } else { 0.0 };
                            local_hessian[i * d + k] = -(identity - unit[i] * unit[k]) / distance;
                        }
                    }
                    radius - distance
                } else {
                    // a half-plane behind the nearest face, its outward normal along that axis
                    let mut axis = 0;
                    for i in 1..d {
                        if depth[i] > depth[axis] {
                            axis = i;
                        }
                    }
                    local_gradient[axis] = -sign[axis];
                    radius - depth[axis]
                };
                // back to the problem's frame: gradient R g, Hessian R H R^T
                let mut rh = [0.0; 9];
                for i in 0..d {
                    gradient[i] = 0.0;
                    for k in 0..d {
                        gradient[i] += local_gradient[k] * m[i * d + k];
                        for j in 0..d {
                            rh[i * d + k] += m[i * d + j] * local_hessian[j * d + k];
                        }
                    }
                }
                for i in 0..d {
                    for k in 0..d {
                        hessian[i * d + k] = 0.0;
                        for j in 0..d {
                            hessian[i * d + k] += rh[i * d + j] * m[k * d + j];
                        }
                    }
                }
                phi
            }
        }
    }
}

/// Built-in shapes as a node field: every shape's phi, gradient and Hessian at every point (n, d).
pub struct NativeField {
    pub dim: usize,
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
        let d = self.dim;
        let n = points.len() / d;
        for (j, shape) in self.shapes.iter().enumerate() {
            for (i, point) in points.chunks_exact(d).enumerate() {
                let at = j * n + i;
                phi[at] = shape.evaluate(
                    &self.quadratics,
                    point,
                    &mut gradient[at * d..at * d + d],
                    &mut hessian[at * d * d..(at + 1) * d * d],
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
        // columns of the rotation: the box's axes (0, 1) and (-1, 0)
        let shape = Shape::plane_box([1.0, 0.0], [2.0, 1.0], 0.5, [0.0, -1.0, 1.0, 0.0]);
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

    /// A box in space of half sizes (1, 2, 3), edge radius 0.5, not turned: beyond a face, an edge
    /// and a corner, phi is minus the distance to it (a plane, a cylinder, a ball), by hand.
    #[test]
    fn a_rounded_box_in_space_is_minus_the_signed_distance_to_its_surface() {
        let identity = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let shape = Shape::Box {
            centre: [0.0; 3],
            half_size: [1.0, 2.0, 3.0],
            radius: 0.5,
            rotation: identity,
        };
        let quadratics = Quadratics::default();
        let (mut g, mut h) = ([0.0; 3], [0.0; 9]);
        // 0.25 above the top face z = 3
        let phi = shape.evaluate(&quadratics, &[0.0, 0.0, 3.25], &mut g, &mut h);
        assert!((phi + 0.25).abs() < 1e-15 && g == [0.0, 0.0, -1.0] && h == [0.0; 9]);
        // beyond the edge x = 0.5, y = 1.5 (inner), by (0.6, 0.8): 1 from it, 0.5 from the surface
        let phi = shape.evaluate(&quadratics, &[1.1, 2.3, 0.0], &mut g, &mut h);
        assert!((phi + 0.5).abs() < 1e-14, "{phi}");
        assert!((g[0] + 0.6).abs() < 1e-14 && (g[1] + 0.8).abs() < 1e-14 && g[2] == 0.0);
        let expected = [-0.64, 0.48, 0.0, 0.48, -0.36, 0.0, 0.0, 0.0, 0.0]; // -(I - u u^T) / 1 on x, y
        assert!(
            h.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-14),
            "{h:?}"
        );
        // beyond the corner (0.5, 1.5, 2.5) by (2, 3, 6) / 7 * 1.4: 1.4 from it, 0.9 from the surface
        let offset = [0.4, 0.6, 1.2];
        let phi = shape.evaluate(
            &quadratics,
            &[0.5 + offset[0], 1.5 + offset[1], 2.5 + offset[2]],
            &mut g,
            &mut h,
        );
        assert!((phi + 0.9).abs() < 1e-14, "{phi}");
        let unit = [2.0 / 7.0, 3.0 / 7.0, 6.0 / 7.0];
        assert!(g.iter().zip(unit).all(|(a, b)| (a + b).abs() < 1e-14));
    }
}
