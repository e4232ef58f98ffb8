//! The little 4x4 matrix arithmetic the importer needs to place lights and cameras in world
//! space. Column-major, as glTF and the pack (`m[column][row]`), in f64 so that deep hierarchies
//! do not accumulate f32 rounding before the result is stored as f32.

pub(crate) type Mat4 = [[f64; 4]; 4];

pub(crate) const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

pub(crate) fn from_f32(m: [[f32; 4]; 4]) -> Mat4 {
    m.map(|c| c.map(f64::from))
}

/// `a * b` (apply `b` first).
pub(crate) fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    std::array::from_fn(|c| std::array::from_fn(|r| (0..4).map(|k| a[k][r] * b[c][k]).sum()))
}

pub(crate) fn translation(m: &Mat4) -> [f64; 3] {
    [m[3][0], m[3][1], m[3][2]]
}

/// A direction through the linear part of `m`.
pub(crate) fn direction(m: &Mat4, v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|r| m[0][r] * v[0] + m[1][r] * v[1] + m[2][r] * v[2])
}

pub(crate) fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let len = dot(v, v).sqrt();
    (len > 1e-12 && len.is_finite()).then(|| v.map(|c| c / len))
}

/// The rotation of `m` with its scale (and any shear) removed, as a unit quaternion xyzw with
/// w >= 0. The local -Z (where a camera looks) is kept exactly and +Y (its up) as nearly as an
/// orthogonal basis allows; a mirroring transform still gives a proper rotation, with X flipped.
/// `None` when the transform flattens Y or Z to nothing.
pub(crate) fn rotation(m: &Mat4) -> Option<[f64; 4]> {
    let column = |c: usize| [m[c][0], m[c][1], m[c][2]];
    let z = normalize(column(2))?;
    let x = normalize(cross(column(1), z))?;
    let y = cross(z, x);
    // r(row, col) of the rotation matrix whose columns are x, y, z.
    let cols = [x, y, z];
    let r = |row: usize, col: usize| cols[col][row];
    let trace = r(0, 0) + r(1, 1) + r(2, 2);
    // Shepperd's method: divide by the largest of the four candidates for stability.
    let q = if trace > 0.0 {
        let s = (trace + 1.0).sqrt() * 2.0;
        [(r(2, 1) - r(1, 2)) / s, (r(0, 2) - r(2, 0)) / s, (r(1, 0) - r(0, 1)) / s, 0.25 * s]
    } else if r(0, 0) > r(1, 1) && r(0, 0) > r(2, 2) {
        let s = (1.0 + r(0, 0) - r(1, 1) - r(2, 2)).sqrt() * 2.0;
        [0.25 * s, (r(0, 1) + r(1, 0)) / s, (r(0, 2) + r(2, 0)) / s, (r(2, 1) - r(1, 2)) / s]
    } else if r(1, 1) > r(2, 2) {
        let s = (1.0 + r(1, 1) - r(0, 0) - r(2, 2)).sqrt() * 2.0;
        [(r(0, 1) + r(1, 0)) / s, 0.25 * s, (r(1, 2) + r(2, 1)) / s, (r(0, 2) - r(2, 0)) / s]
    } else {
        let s = (1.0 + r(2, 2) - r(0, 0) - r(1, 1)).sqrt() * 2.0;
        [(r(0, 2) + r(2, 0)) / s, (r(1, 2) + r(2, 1)) / s, 0.25 * s, (r(1, 0) - r(0, 1)) / s]
    };
    let len = q.iter().map(|c| c * c).sum::<f64>().sqrt();
    let sign = if q[3] < 0.0 { -1.0 } else { 1.0 };
    (len.is_finite() && len > 0.0).then(|| q.map(|c| sign * c / len))
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotation_of_a_scaled_turn_is_the_turn() {
        // 90 degrees about Y, scaled by (2, 3, 4): columns R * S.
        let m: Mat4 = [[0.0, 0.0, -2.0, 0.0], [0.0, 3.0, 0.0, 0.0], [4.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0, 1.0]];
        let q = rotation(&m).unwrap();
        let h = std::f64::consts::FRAC_1_SQRT_2;
        assert!(q.iter().zip([0.0, h, 0.0, h]).all(|(a, b)| (a - b).abs() < 1e-12), "{q:?}");
        assert_eq!(translation(&m), [1.0, 2.0, 3.0]);
        let d = normalize(direction(&m, [0.0, 0.0, -1.0])).unwrap();
        assert!(d.iter().zip([-1.0, 0.0, 0.0]).all(|(a, b)| (a - b).abs() < 1e-12), "{d:?}");
        assert_eq!(mul(&IDENTITY, &m), m);
        assert_eq!(rotation(&[[0.0; 4]; 4]), None, "a transform scaled to nothing has no rotation");
    }
}
