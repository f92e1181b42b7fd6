//! The conversions an IRL template may call, evaluated when compiling (docs/LANGUAGES.md,
//! "Conversions"), and the way their results are written into the program text.
//!
//! The plan's frames are KUKA's `(x, y, z, a, b, c)` in mm and degrees: `A` about Z, then `B` about
//! the new Y, then `C` about the new X (intrinsic Z-Y'-X'', so `R = Rz(A)·Ry(B)·Rx(C)`). Other
//! languages want metres, radians, a quaternion (ABB RAPID, `w, x, y, z`) or a rotation vector (UR,
//! axis times angle in radians); [`Conversion`] computes them and [`format_results`] writes them.
//!
//! Pure: no I/O, std only. The angle functions reduce degrees exactly before taking sines, so
//! multiples of 90° give exact zeros and ones (a half turn has `w == 0`, not `6e-17`).

use std::f64::consts::FRAC_1_SQRT_2;

/// A conversion an IRL template may call.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Conversion {
    /// `m(P)`: millimetres → metres.
    M,
    /// `mm(P)`: metres → millimetres.
    Mm,
    /// `rad(P)`: degrees → radians.
    Rad,
    /// `deg(P)`: radians → degrees.
    Deg,
    /// `quat(A, B, C)`: KUKA angles in degrees → the unit quaternion `w, x, y, z`.
    Quat,
    /// `rotvec(A, B, C)`: KUKA angles in degrees → the rotation vector `rx, ry, rz` in radians.
    Rotvec,
}

impl Conversion {
    /// `m`, `mm`, `rad`, `deg`, `quat`, `rotvec` (exact lower-case spelling only) → the conversion.
    pub fn from_name(name: &str) -> Option<Conversion> {
        Some(match name {
            "m" => Conversion::M,
            "mm" => Conversion::Mm,
            "rad" => Conversion::Rad,
            "deg" => Conversion::Deg,
            "quat" => Conversion::Quat,
            "rotvec" => Conversion::Rotvec,
            _ => return None,
        })
    }

    /// The name a template calls it by (the inverse of [`Conversion::from_name`]).
    pub fn name(self) -> &'static str {
        match self {
            Conversion::M => "m",
            Conversion::Mm => "mm",
            Conversion::Rad => "rad",
            Conversion::Deg => "deg",
            Conversion::Quat => "quat",
            Conversion::Rotvec => "rotvec",
        }
    }

    /// Number of arguments: 1, except quat and rotvec: 3.
    pub fn arity(self) -> usize {
        match self {
            Conversion::Quat | Conversion::Rotvec => 3,
            _ => 1,
        }
    }

    /// Number of results: 1, quat 4, rotvec 3.
    pub fn results(self) -> usize {
        match self {
            Conversion::Quat => 4,
            Conversion::Rotvec => 3,
            _ => 1,
        }
    }

    /// Applies it; `args.len() == self.arity()`; writes `self.results()` numbers into `out` (the
    /// rest of `out` is left as it was).
    ///
    /// `quat` gives the canonical sign: `w > 0`, or, when `w` prints as zero (`|w| < 5e-7`), the
    /// first of `x, y, z` that does not print as zero positive. `rotvec` is that quaternion's axis
    /// times its angle `2·atan2(|v|, w)`, so its direction agrees with `quat`'s `x, y, z`: the
    /// angle is in `[0, π]`, or just above `π` (by less than 1e-6) when the canonical sign of a
    /// half turn needs it, so the rotation stays exact. A non-finite argument gives non-finite
    /// results (which [`format_number`] refuses).
    ///
    /// # Panics
    ///
    /// If `args.len() != self.arity()`.
    pub fn apply(self, args: &[f64], out: &mut [f64; 4]) {
        assert_eq!(
            args.len(),
            self.arity(),
            "{} takes {} arguments",
            self.name(),
            self.arity()
        );
        match self {
            Conversion::M => out[0] = args[0] / 1000.0,
            Conversion::Mm => out[0] = args[0] * 1000.0,
            Conversion::Rad => out[0] = args[0].to_radians(),
            Conversion::Deg => out[0] = args[0].to_degrees(),
            Conversion::Quat => *out = quat(args[0], args[1], args[2]),
            Conversion::Rotvec => {
                let [rx, ry, rz] = rotvec(quat(args[0], args[1], args[2]));
                out[..3].copy_from_slice(&[rx, ry, rz]);
            }
        }
    }
}

/// A value below this prints as zero (6 decimals, half away from zero).
const PRINTS_AS_ZERO: f64 = 5e-7;

/// `(sin, cos)` of an angle in degrees, reduced exactly first: whole multiples of 90° give exact
/// `0` and `±1`, ±45° gives exactly `√½`, and large angles lose nothing to `π`'s rounding.
fn sin_cos_deg(deg: f64) -> (f64, f64) {
    let r = deg % 360.0; // exact
    let quadrant = (r / 90.0).round();
    let rest = r - quadrant * 90.0; // exact (Sterbenz), |rest| <= 45
    let (s, c) = if rest.abs() == 45.0 {
        (FRAC_1_SQRT_2.copysign(rest), FRAC_1_SQRT_2)
    } else {
        rest.to_radians().sin_cos()
    };
    // `quadrant` is in -4..=4 (or NaN, which becomes 0 and keeps the NaN in `s` and `c`).
    match (quadrant as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// The unit quaternion `[w, x, y, z]` of KUKA's `A, B, C` (degrees): `qz(A)·qy(B)·qx(C)`, with
/// the canonical sign (see [`Conversion::apply`]). Exact at gimbal lock (`B = ±90°`): no angles
/// are recovered from a matrix.
fn quat(a: f64, b: f64, c: f64) -> [f64; 4] {
    let (sz, cz) = sin_cos_deg(a / 2.0);
    let (sy, cy) = sin_cos_deg(b / 2.0);
    let (sx, cx) = sin_cos_deg(c / 2.0);
    let mut q = [
        cz * cy * cx + sz * sy * sx,
        cz * cy * sx - sz * sy * cx,
        cz * sy * cx + sz * cy * sx,
        sz * cy * cx - cz * sy * sx,
    ];
    let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if norm > 0.0 {
        q.iter_mut().for_each(|v| *v /= norm);
    }
    let leading = if q[0].abs() >= PRINTS_AS_ZERO {
        q[0]
    } else {
        q[1..]
            .iter()
            .copied()
            .find(|v| v.abs() >= PRINTS_AS_ZERO)
            .unwrap_or(q[0])
    };
    if leading < 0.0 {
        q.iter_mut().for_each(|v| *v = -*v);
    }
    q
}

/// The rotation vector (axis times angle, radians) of a unit quaternion `[w, x, y, z]`: the angle
/// is `2·atan2(|v|, w)`, the axis `v / |v|`; near the identity a series replaces `atan2(n, w) / n`.
fn rotvec([w, x, y, z]: [f64; 4]) -> [f64; 3] {
    let n = (x * x + y * y + z * z).sqrt();
    // angle / |v|; for n < 1e-6 (so w ≈ 1) the series' next term is below 1e-24.
    let k = if n < 1e-6 {
        2.0 / w * (1.0 - n * n / (3.0 * w * w))
    } else {
        2.0 * n.atan2(w) / n
    };
    [x * k, y * k, z * k]
}

/// A result as the program text shows it: at most 6 decimals (rounded half away from zero), no
/// trailing zeros, no trailing `.`, no `-0` (anything that rounds to zero is `0`), never an
/// exponent. `None` for a non-finite value or |x| >= 1e15 (the caller reports "out of range").
///
/// The rounding is done on the shortest decimal that reads back as `x` (what `{}` prints), so
/// `5e-7` gives `0.000001` although the nearest `f64` is a hair below it.
pub fn format_number(x: f64) -> Option<String> {
    let mut out = String::new();
    write_number(x, &mut out).then_some(out)
}

/// [`format_number`] appended to `out`, without allocating; `false` (and `out` unchanged) for a
/// value that cannot be written.
pub fn write_number(x: f64, out: &mut String) -> bool {
    use std::fmt::Write as _;
    const DECIMALS: usize = 6;
    if !x.is_finite() || x.abs() >= 1e15 {
        return false;
    }
    if x.abs() < 5e-7 {
        // Rounds to zero (and its shortest form may be hundreds of digits long).
        out.push('0');
        return true;
    }
    if let Some(n) = fast_micros(x.abs()) {
        // Millionths, away from a tie: the same digits the decimal rounding below gives.
        if n == 0 {
            out.push('0');
            return true;
        }
        if x < 0.0 {
            out.push('-');
        }
        push_u64(out, n / 1_000_000);
        let mut frac = n % 1_000_000;
        if frac != 0 {
            out.push('.');
            let mut width = 6;
            while frac % 10 == 0 {
                frac /= 10;
                width -= 1;
            }
            let digits = frac.ilog10() as usize + 1;
            for _ in digits..width {
                out.push('0');
            }
            push_u64(out, frac);
        }
        return true;
    }
    // Display of a finite f64 never uses an exponent: digits, maybe `.` and more digits. Below
    // 1e15 the shortest form that reads back fits easily in 64 bytes.
    let mut buf = StackText {
        bytes: [0; 64],
        len: 0,
    };
    if write!(buf, "{}", x.abs()).is_err() {
        return false;
    }
    let text = &buf.bytes[..buf.len];
    let (int, frac) = match text.iter().position(|&b| b == b'.') {
        Some(i) => (&text[..i], &text[i + 1..]),
        None => (text, &[][..]),
    };
    // d[0] takes a carry out of the integer digits.
    let mut d = [b'0'; 48];
    let il = int.len();
    if il + DECIMALS + 1 > d.len() {
        return false;
    }
    d[1..1 + il].copy_from_slice(int);
    for k in 0..DECIMALS {
        d[1 + il + k] = frac.get(k).copied().unwrap_or(b'0');
    }
    let end = 1 + il + DECIMALS;
    if frac.get(DECIMALS).is_some_and(|&c| c >= b'5') {
        // Round up (away from zero): carry through the nines; d[0] is '0', so it stops there.
        let mut i = end - 1;
        while d[i] == b'9' {
            d[i] = b'0';
            i -= 1;
        }
        d[i] += 1;
    }
    let int_digits = if d[0] == b'0' {
        &d[1..1 + il]
    } else {
        &d[..1 + il]
    };
    let frac_digits = &d[1 + il..end];
    let frac_digits = &frac_digits[..frac_digits
        .iter()
        .rposition(|&c| c != b'0')
        .map_or(0, |i| i + 1)];
    if frac_digits.is_empty() && int_digits.iter().all(|&c| c == b'0') {
        out.push('0');
        return true;
    }
    if x < 0.0 {
        out.push('-');
    }
    out.extend(int_digits.iter().map(|&c| c as char));
    if !frac_digits.is_empty() {
        out.push('.');
        out.extend(frac_digits.iter().map(|&c| c as char));
    }
    true
}

/// `a` (not negative) in millionths, rounded half up, when that is what rounding its shortest
/// decimal form gives (`None`: not sure; [`write_number`]'s decimal path decides).
fn fast_micros(a: f64) -> Option<u64> {
    // Below 1e7 an f64 is within 1e-9 of its shortest decimal form and `a * 1e6` within 0.002
    // of the exact product: the two round alike unless the millionths are within 0.01 of a tie.
    if a >= 1e7 {
        return None;
    }
    let scaled = a * 1e6;
    let floor = scaled.floor();
    let frac = scaled - floor;
    if (frac - 0.5).abs() <= 0.01 {
        return None;
    }
    Some(floor as u64 + u64::from(frac > 0.5))
}

/// Appends the decimal digits of `n`.
pub(crate) fn push_u64(out: &mut String, mut n: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    loop {
        i -= 1;
        buf[i] = b'0' + (n % 10) as u8;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    out.extend(buf[i..].iter().map(|&b| b as char));
}

/// A fixed buffer `write!` formats into (no allocation, no I/O adapter).
struct StackText {
    bytes: [u8; 64],
    len: usize,
}

impl std::fmt::Write for StackText {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        let end = self.len + s.len();
        let dst = self.bytes.get_mut(self.len..end).ok_or(std::fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

/// Writes the results of one conversion joined by ", " (e.g. quat → "1, 0, 0, 0"); `None` if any
/// of them is non-finite or |x| >= 1e15, as [`format_number`].
pub fn format_results(values: &[f64]) -> Option<String> {
    let mut out = String::new();
    write_results(values, &mut out).then_some(out)
}

/// [`format_results`] appended to `out`; `false` (and `out` as it was) when one cannot be
/// written.
pub fn write_results(values: &[f64], out: &mut String) -> bool {
    let at = out.len();
    for (k, &v) in values.iter().enumerate() {
        if k > 0 {
            out.push_str(", ");
        }
        if !write_number(v, out) {
            out.truncate(at);
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    type Mat = [[f64; 3]; 3];

    const ALL: [Conversion; 6] = [
        Conversion::M,
        Conversion::Mm,
        Conversion::Rad,
        Conversion::Deg,
        Conversion::Quat,
        Conversion::Rotvec,
    ];

    fn run(conv: Conversion, args: &[f64]) -> Vec<f64> {
        let mut out = [f64::NAN; 4];
        conv.apply(args, &mut out);
        out[..conv.results()].to_vec()
    }

    fn mul(a: &Mat, b: &Mat) -> Mat {
        let mut m = [[0.0; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
            }
        }
        m
    }

    /// `Rz(A)·Ry(B)·Rx(C)` from the elementary matrices, independently of the module.
    fn kuka_matrix(a: f64, b: f64, c: f64) -> Mat {
        let (sa, ca) = a.to_radians().sin_cos();
        let (sb, cb) = b.to_radians().sin_cos();
        let (sc, cc) = c.to_radians().sin_cos();
        let rz = [[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]];
        let ry = [[cb, 0.0, sb], [0.0, 1.0, 0.0], [-sb, 0.0, cb]];
        let rx = [[1.0, 0.0, 0.0], [0.0, cc, -sc], [0.0, sc, cc]];
        mul(&mul(&rz, &ry), &rx)
    }

    fn quat_matrix(q: &[f64]) -> Mat {
        let [w, x, y, z] = [q[0], q[1], q[2], q[3]];
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// Rodrigues: `I + sin θ·K + (1 − cos θ)·K²` with `K` the cross-product matrix of the axis.
    fn rotvec_matrix(r: &[f64]) -> Mat {
        let theta = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        let mut m = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        if theta == 0.0 {
            return m;
        }
        let [x, y, z] = [r[0] / theta, r[1] / theta, r[2] / theta];
        let k = [[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]];
        let k2 = mul(&k, &k);
        let (s, c) = theta.sin_cos();
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += s * k[i][j] + (1.0 - c) * k2[i][j];
            }
        }
        m
    }

    fn max_diff(a: &Mat, b: &Mat) -> f64 {
        (0..9)
            .map(|i| (a[i / 3][i % 3] - b[i / 3][i % 3]).abs())
            .fold(0.0, f64::max)
    }

    fn assert_close(got: &[f64], want: &[f64]) {
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "got {got:?}, want {want:?}");
        }
    }

    /// Checks both rotation conversions of `(a, b, c)` against the independent matrix.
    fn assert_rotation(a: f64, b: f64, c: f64) {
        let want = kuka_matrix(a, b, c);
        let q = run(Conversion::Quat, &[a, b, c]);
        let r = run(Conversion::Rotvec, &[a, b, c]);
        assert!(
            max_diff(&quat_matrix(&q), &want) < 1e-9,
            "quat {q:?} for {a}, {b}, {c}"
        );
        assert!(
            max_diff(&rotvec_matrix(&r), &want) < 1e-9,
            "rotvec {r:?} for {a}, {b}, {c}"
        );
    }

    #[test]
    fn names_round_trip_and_are_exact() {
        for conv in ALL {
            assert_eq!(Conversion::from_name(conv.name()), Some(conv));
        }
        for bad in [
            "M", "Mm", "RAD", "Quat", " deg", "rotvec ", "", "cm", "euler",
        ] {
            assert_eq!(Conversion::from_name(bad), None, "{bad:?}");
        }
    }

    #[test]
    fn arity_and_results() {
        let shape: Vec<_> = ALL.iter().map(|c| (c.arity(), c.results())).collect();
        assert_eq!(shape, [(1, 1), (1, 1), (1, 1), (1, 1), (3, 4), (3, 3)]);
    }

    #[test]
    fn unit_conversions() {
        assert_eq!(run(Conversion::M, &[1500.0]), [1.5]);
        assert_eq!(run(Conversion::M, &[-250.0]), [-0.25]);
        assert_eq!(run(Conversion::Mm, &[1.5]), [1500.0]);
        assert_eq!(run(Conversion::Mm, &[-0.25]), [-250.0]);
        assert_close(&run(Conversion::Rad, &[180.0]), &[PI]);
        assert_close(&run(Conversion::Rad, &[-90.0]), &[-FRAC_PI_2]);
        assert_close(&run(Conversion::Deg, &[PI]), &[180.0]);
        assert_close(&run(Conversion::Deg, &[FRAC_PI_2]), &[90.0]);
        assert_eq!(
            format_results(&run(Conversion::M, &[123.4])).unwrap(),
            "0.1234"
        );
        assert_eq!(
            format_results(&run(Conversion::Rad, &[90.0])).unwrap(),
            "1.570796"
        );
        assert_eq!(
            format_results(&run(Conversion::Deg, &[1.0])).unwrap(),
            "57.29578"
        );
    }

    #[test]
    fn apply_leaves_the_rest_of_out_alone() {
        let mut out = [9.0; 4];
        Conversion::Rotvec.apply(&[0.0, 0.0, 0.0], &mut out);
        assert_eq!(out[3], 9.0);
        Conversion::M.apply(&[1.0], &mut out);
        assert_eq!(out[1..], [0.0, 0.0, 9.0]);
    }

    #[test]
    #[should_panic(expected = "quat takes 3 arguments")]
    fn apply_checks_the_argument_count() {
        Conversion::Quat.apply(&[1.0], &mut [0.0; 4]);
    }

    #[test]
    fn identity() {
        assert_eq!(
            run(Conversion::Quat, &[0.0, 0.0, 0.0]),
            [1.0, 0.0, 0.0, 0.0]
        );
        assert_eq!(run(Conversion::Rotvec, &[0.0, 0.0, 0.0]), [0.0, 0.0, 0.0]);
        assert_eq!(
            format_results(&run(Conversion::Quat, &[0.0, 0.0, 0.0])).unwrap(),
            "1, 0, 0, 0"
        );
        assert_eq!(
            format_results(&run(Conversion::Rotvec, &[0.0, 0.0, 0.0])).unwrap(),
            "0, 0, 0"
        );
        // Whole turns are the identity too, with the canonical sign.
        assert_eq!(
            run(Conversion::Quat, &[360.0, -720.0, 360.0]),
            [1.0, 0.0, 0.0, 0.0]
        );
        assert_eq!(
            format_results(&run(Conversion::Rotvec, &[360.0, 0.0, -360.0])).unwrap(),
            "0, 0, 0"
        );
    }

    #[test]
    fn ninety_degrees_about_each_axis() {
        let h = FRAC_1_SQRT_2;
        assert_close(&run(Conversion::Quat, &[90.0, 0.0, 0.0]), &[h, 0.0, 0.0, h]);
        assert_close(&run(Conversion::Quat, &[0.0, 90.0, 0.0]), &[h, 0.0, h, 0.0]);
        assert_close(&run(Conversion::Quat, &[0.0, 0.0, 90.0]), &[h, h, 0.0, 0.0]);
        assert_close(
            &run(Conversion::Rotvec, &[90.0, 0.0, 0.0]),
            &[0.0, 0.0, FRAC_PI_2],
        );
        assert_close(
            &run(Conversion::Rotvec, &[0.0, 90.0, 0.0]),
            &[0.0, FRAC_PI_2, 0.0],
        );
        assert_close(
            &run(Conversion::Rotvec, &[0.0, 0.0, 90.0]),
            &[FRAC_PI_2, 0.0, 0.0],
        );
        assert_close(
            &run(Conversion::Rotvec, &[-90.0, 0.0, 0.0]),
            &[0.0, 0.0, -FRAC_PI_2],
        );
        let text = |c, args: &[f64]| format_results(&run(c, args)).unwrap();
        assert_eq!(
            text(Conversion::Quat, &[90.0, 0.0, 0.0]),
            "0.707107, 0, 0, 0.707107"
        );
        assert_eq!(
            text(Conversion::Quat, &[0.0, -90.0, 0.0]),
            "0.707107, 0, -0.707107, 0"
        );
        assert_eq!(
            text(Conversion::Rotvec, &[0.0, 0.0, 90.0]),
            "1.570796, 0, 0"
        );
        for (a, b, c) in [(90.0, 0.0, 0.0), (0.0, 90.0, 0.0), (0.0, 0.0, 90.0)] {
            assert_rotation(a, b, c);
        }
    }

    #[test]
    fn general_case_matches_the_matrix() {
        assert_rotation(30.0, 45.0, 60.0);
        assert_rotation(-123.4, 17.5, 171.25);
        assert_rotation(200.0, -80.0, -300.0);
        // The value of this one (w, x, y, z) from the half-angle product, computed elsewhere.
        let q = run(Conversion::Quat, &[30.0, 45.0, 60.0]);
        assert_eq!(
            format_results(&q).unwrap(),
            "0.822363, 0.360423, 0.43968, 0.02226"
        );
    }

    #[test]
    fn gimbal_lock() {
        for b in [90.0, -90.0] {
            assert_rotation(30.0, b, 60.0);
            assert_rotation(-45.0, b, 10.0);
            assert_rotation(170.0, b, -170.0);
        }
        // At B = 90° only A − C matters (A + C at B = −90°); the quaternion is the same one.
        let q1 = run(Conversion::Quat, &[30.0, 90.0, 60.0]);
        let q2 = run(Conversion::Quat, &[0.0, 90.0, 30.0]);
        assert_close(&q1, &q2);
        let q3 = run(Conversion::Quat, &[30.0, -90.0, 60.0]);
        let q4 = run(Conversion::Quat, &[90.0, -90.0, 0.0]);
        assert_close(&q3, &q4);
    }

    #[test]
    fn half_turns_have_the_canonical_sign() {
        let text = |args: &[f64]| {
            let q = format_results(&run(Conversion::Quat, args)).unwrap();
            let r = format_results(&run(Conversion::Rotvec, args)).unwrap();
            (q, r)
        };
        for args in [[180.0, 0.0, 0.0], [-180.0, 0.0, 0.0], [540.0, 0.0, 0.0]] {
            assert_eq!(
                text(&args),
                ("0, 0, 0, 1".into(), "0, 0, 3.141593".into()),
                "{args:?}"
            );
        }
        for args in [[0.0, 180.0, 0.0], [0.0, -180.0, 0.0]] {
            assert_eq!(
                text(&args),
                ("0, 0, 1, 0".into(), "0, 3.141593, 0".into()),
                "{args:?}"
            );
        }
        for args in [[0.0, 0.0, 180.0], [0.0, 0.0, -180.0]] {
            assert_eq!(
                text(&args),
                ("0, 1, 0, 0".into(), "3.141593, 0, 0".into()),
                "{args:?}"
            );
        }
        // A = 180, C = 180 is a half turn about Y; A = 180, B = 90 one about (1, 0, -1)/√2.
        assert_eq!(
            text(&[180.0, 0.0, 180.0]),
            ("0, 0, 1, 0".into(), "0, 3.141593, 0".into())
        );
        let about_x_minus_z = ("0, 0.707107, 0, -0.707107", "2.221441, 0, -2.221441");
        // B = ±180° (and A = ±180°) are one rotation, and the quaternion's sign flips between
        // them: the output is the same, with the first non-zero component positive.
        for args in [
            [180.0, 90.0, 0.0],
            [-180.0, 90.0, 0.0],
            [180.0, 90.0, 360.0],
        ] {
            let (q, r) = text(&args);
            assert_eq!((q.as_str(), r.as_str()), about_x_minus_z, "{args:?}");
        }
        for args in [
            [0.0, 180.0, 90.0],
            [0.0, -180.0, 90.0],
            [0.0, 180.0, -270.0],
        ] {
            let (q, r) = text(&args);
            assert_eq!(q, "0, 0, 0.707107, -0.707107", "{args:?}");
            assert_eq!(r, "0, 2.221441, -2.221441", "{args:?}");
        }
        assert_rotation(0.0, 180.0, 90.0);
        assert_rotation(180.0, 90.0, 0.0);
    }

    #[test]
    fn non_finite_arguments_are_refused_by_the_formatter() {
        for conv in ALL {
            let args = vec![f64::NAN; conv.arity()];
            assert_eq!(format_results(&run(conv, &args)), None, "{conv:?}");
            let args = vec![f64::INFINITY; conv.arity()];
            assert_eq!(format_results(&run(conv, &args)), None, "{conv:?}");
        }
    }

    #[test]
    fn formatting() {
        let f = format_number;
        assert_eq!(f(0.1 + 0.2).as_deref(), Some("0.3"));
        assert_eq!(f(1.0).as_deref(), Some("1"));
        assert_eq!(f(0.0).as_deref(), Some("0"));
        assert_eq!(f(-0.0).as_deref(), Some("0"));
        assert_eq!(f(-0.0000001).as_deref(), Some("0"));
        assert_eq!(f(-1.5).as_deref(), Some("-1.5"));
        assert_eq!(f(123456.7890126).as_deref(), Some("123456.789013"));
        assert_eq!(f(1e20), None);
        assert_eq!(f(f64::NAN), None);
        assert_eq!(f(f64::INFINITY), None);
        assert_eq!(f(f64::NEG_INFINITY), None);
        assert_eq!(f(2.5e-7).as_deref(), Some("0"));
        assert_eq!(f(5e-7).as_deref(), Some("0.000001"));
        assert_eq!(f(-5e-7).as_deref(), Some("-0.000001"));
        assert_eq!(f(4.99999e-7).as_deref(), Some("0"));
        assert_eq!(f(1e14).as_deref(), Some("100000000000000"));
        assert_eq!(f(-1e14).as_deref(), Some("-100000000000000"));
        assert_eq!(f(1e15), None);
        assert_eq!(f(-1e15), None);
        assert_eq!(f(999999999999999.9).as_deref(), Some("999999999999999.9"));
        assert_eq!(f(0.9999996).as_deref(), Some("1"));
        assert_eq!(f(-9.9999995).as_deref(), Some("-10"));
        assert_eq!(f(99.9999994).as_deref(), Some("99.999999"));
        assert_eq!(f(0.0000015).as_deref(), Some("0.000002"));
        assert_eq!(f(-2.5).as_deref(), Some("-2.5"));
        assert_eq!(f(1e-300).as_deref(), Some("0"));
        assert_eq!(f(1234.5).as_deref(), Some("1234.5"));
        assert_eq!(f(100.0).as_deref(), Some("100"));
        assert_eq!(f(10.1000004).as_deref(), Some("10.1"));
    }

    #[test]
    fn formatting_results() {
        assert_eq!(
            format_results(&[1.0, 0.0, -0.0, 0.5]).as_deref(),
            Some("1, 0, 0, 0.5")
        );
        assert_eq!(format_results(&[2.0]).as_deref(), Some("2"));
        assert_eq!(format_results(&[]).as_deref(), Some(""));
        assert_eq!(format_results(&[1.0, f64::NAN]), None);
        assert_eq!(format_results(&[1e15, 1.0]), None);
    }

    fn angle() -> impl Strategy<Value = f64> {
        prop_oneof![
            4 => -360.0..=360.0f64,
            // Multiples of 45° and 90°: half turns, gimbal lock, the canonical-sign branch.
            1 => (-8i32..=8).prop_map(|k| f64::from(k) * 45.0),
        ]
    }

    proptest! {
        #[test]
        fn quat_is_a_canonical_unit_quaternion(a in angle(), b in angle(), c in angle()) {
            let q = run(Conversion::Quat, &[a, b, c]);
            let norm = q.iter().map(|v| v * v).sum::<f64>().sqrt();
            prop_assert!((norm - 1.0).abs() < 1e-12, "{q:?}");
            // w >= 0 as printed; when it prints as 0 the first printed non-zero is positive.
            prop_assert!(q[0] > -PRINTS_AS_ZERO, "{q:?}");
            if q[0].abs() < PRINTS_AS_ZERO {
                let first = q[1..].iter().find(|v| v.abs() >= PRINTS_AS_ZERO).unwrap();
                prop_assert!(*first > 0.0, "{q:?}");
            }
            prop_assert!(format_results(&q).is_some());
        }

        #[test]
        fn quat_gives_the_kuka_rotation(a in angle(), b in angle(), c in angle()) {
            let q = run(Conversion::Quat, &[a, b, c]);
            let d = max_diff(&quat_matrix(&q), &kuka_matrix(a, b, c));
            prop_assert!(d < 1e-9, "{q:?}: {d}");
        }

        #[test]
        fn rotvec_gives_the_kuka_rotation(a in angle(), b in angle(), c in angle()) {
            let r = run(Conversion::Rotvec, &[a, b, c]);
            let d = max_diff(&rotvec_matrix(&r), &kuka_matrix(a, b, c));
            prop_assert!(d < 1e-9, "{r:?}: {d}");
            let theta = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            prop_assert!(theta <= PI + 1e-6, "{r:?}");
        }

        #[test]
        fn quat_and_rotvec_agree(a in angle(), b in angle(), c in angle()) {
            let q = run(Conversion::Quat, &[a, b, c]);
            let r = run(Conversion::Rotvec, &[a, b, c]);
            prop_assert!(max_diff(&quat_matrix(&q), &rotvec_matrix(&r)) < 1e-9);
            // Same direction: the rotation vector is a non-negative multiple of q's vector part,
            // with the angle 2·acos(w).
            let theta = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            prop_assert!((theta - 2.0 * q[0].clamp(-1.0, 1.0).acos()).abs() < 1e-6);
            for i in 0..3 {
                prop_assert!(r[i] * q[i + 1] >= 0.0, "{q:?} {r:?}");
            }
        }

        #[test]
        fn formatting_matches_rounding(x in -1e9..1e9f64) {
            let text = format_number(x).unwrap();
            prop_assert!(!text.contains('e') && !text.ends_with('.') && text != "-0");
            if let Some((_, frac)) = text.split_once('.') {
                prop_assert!(frac.len() <= 6 && !frac.ends_with('0'));
            }
            let back: f64 = text.parse().unwrap();
            prop_assert!((back - x).abs() <= 5e-7 + x.abs() * 1e-15, "{x} → {text}");
        }
    }

    proptest! {
        /// The fast path (millionths away from a tie) writes what the decimal rounding of the
        /// shortest form writes.
        #[test]
        fn fast_path_agrees_with_the_decimal_rounding(x in -1e12f64..1e12, k in 0u32..19) {
            let x = x / 10f64.powi(k as i32);
            let mut fast = String::new();
            prop_assert!(write_number(x, &mut fast));
            prop_assert_eq!(fast, slow(x));
        }
    }

    /// The slow path alone: the shortest form, rounded as decimal digits.
    fn slow(x: f64) -> String {
        if x.abs() < 5e-7 {
            return "0".to_owned();
        }
        let text = x.abs().to_string();
        let (int, frac) = text.split_once('.').unwrap_or((&text, ""));
        let mut digits: Vec<u8> = int
            .bytes()
            .chain(frac.bytes().chain(std::iter::repeat(b'0')).take(6))
            .collect();
        if frac.as_bytes().get(6).is_some_and(|&d| d >= b'5') {
            match digits.iter().rposition(|&d| d != b'9') {
                Some(i) => {
                    digits[i] += 1;
                    digits[i + 1..].fill(b'0');
                }
                None => {
                    digits.fill(b'0');
                    digits.insert(0, b'1');
                }
            }
        }
        let (int, frac) = digits.split_at(digits.len() - 6);
        let frac = &frac[..frac.iter().rposition(|&d| d != b'0').map_or(0, |i| i + 1)];
        let int = std::str::from_utf8(int).unwrap().trim_start_matches('0');
        let int = if int.is_empty() { "0" } else { int };
        if frac.is_empty() && int == "0" {
            return "0".to_owned();
        }
        let mut out = String::new();
        if x < 0.0 {
            out.push('-');
        }
        out.push_str(int);
        if !frac.is_empty() {
            out.push('.');
            out.push_str(std::str::from_utf8(frac).unwrap());
        }
        out
    }
}
