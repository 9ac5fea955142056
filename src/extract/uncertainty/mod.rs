//! How well a fitted plane is known, from its inliers and the sensor's noise.
//!
//! The plane is fitted by least squares (PCA) to its inliers. Linearised at their centroid,
//! a small error of the fit tilts the normal by (a1, a2) rad towards two in-plane axes and
//! shifts the plane by `shift` m along the normal there; each inlier's residual moves by
//! `a1 (p - c).e1 + a2 (p - c).e2 - shift`. A depth pixel is noisy along its ray; the part
//! of that noise across the plane is what moves the fit. Its standard deviation follows
//! the L515's shape (as `synth::noise` models it): proportional to 0.5 + 0.5 r / 1 m along
//! the ray at range r, grown by 1 / sqrt(cos) at incidence cos, times cos across the
//! plane. The scale of that shape is the fit's own: the residuals' weighted RMS, so no
//! sensor constant is needed and a noisier sensor reports a larger covariance. The
//! covariance of (a1, a2, shift) for the unweighted fit is then the sandwich
//! H^-1 (sum s_i^2 a_i a_i^T) H^-1 with H = sum a_i a_i^T.

use nalgebra::{Matrix2, Matrix3, SymmetricEigen, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::cpu::ransac::PlaneFit;
use super::cpu::simd::{Level, level};
#[cfg(target_arch = "aarch64")]
use simd::neon;
#[cfg(target_arch = "x86_64")]
use simd::{avx2, avx512};

mod simd;

/// The covariance of a fitted plane: its normal tilts by (a1, a2) rad towards `axes[0]`
/// and `axes[1]`, and it shifts by `shift` m along the normal at `centre`; `cov` is the
/// covariance of (a1, a2, shift). All in the polygon's frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlaneUncertainty {
    pub centre: [f64; 3],
    pub axes: [[f64; 3]; 2],
    pub cov: [[f64; 3]; 3],
}

impl PlaneUncertainty {
    /// Standard deviation of the normal's direction along its worst axis, rad.
    pub fn tilt_sigma_rad(&self) -> f64 {
        let [[a, b, _], [_, d, _], _] = self.cov;
        // Largest eigenvalue of the 2 x 2 tilt block.
        let (m, r) = ((a + d) / 2.0, (((a - d) / 2.0).powi(2) + b * b).sqrt());
        (m + r).max(0.0).sqrt()
    }

    /// Standard deviation of the plane's position along its normal at `centre`, m.
    pub fn offset_sigma_m(&self) -> f64 {
        self.cov[2][2].max(0.0).sqrt()
    }

    /// (a1, a2, shift) of another plane (unit normal n, offset d) against this one's:
    /// what `cov` is the covariance of.
    pub fn error_of(&self, normal: &Vector3<f64>, offset: f64) -> Vector3<f64> {
        let c = Vector3::from(self.centre);
        Vector3::new(
            normal.dot(&Vector3::from(self.axes[0])),
            normal.dot(&Vector3::from(self.axes[1])),
            -(normal.dot(&c) + offset),
        )
    }

    /// Whether it says anything: a covariance with positive variances (a default, all
    /// zero, is "unknown", not "exact").
    pub fn is_known(&self) -> bool {
        (0..3).all(|k| self.cov[k][k] > 0.0 && self.cov[k][k].is_finite())
    }

    /// The same errors about another centre and pair of in-plane axes of (nearly) the same
    /// plane: the tilts projected onto the new axes, and the shift at the new centre, which
    /// the tilts move by their lever arm.
    pub fn expressed_at(&self, centre: [f64; 3], axes: [[f64; 3]; 2]) -> PlaneUncertainty {
        let (e, f) = (self.axes.map(Vector3::from), axes.map(Vector3::from));
        let d = Vector3::from(centre) - Vector3::from(self.centre);
        #[rustfmt::skip]
        let j = Matrix3::new(
            e[0].dot(&f[0]), e[1].dot(&f[0]), 0.0,
            e[0].dot(&f[1]), e[1].dot(&f[1]), 0.0,
            -e[0].dot(&d), -e[1].dot(&d), 1.0,
        );
        let cov = j * Matrix3::from(self.cov).transpose() * j.transpose();
        PlaneUncertainty { centre, axes, cov: cov.transpose().into() }
    }

    /// The uncertainty of both estimates combined, as independent measurements of one
    /// plane (information added), about this one's centre and axes. An unknown side adds
    /// nothing.
    pub fn fused_with(&self, other: &PlaneUncertainty) -> PlaneUncertainty {
        if !other.is_known() {
            return *self;
        }
        let theirs = other.expressed_at(self.centre, self.axes);
        if !self.is_known() {
            return theirs;
        }
        let inverse = |c: [[f64; 3]; 3]| Matrix3::from(c).try_inverse();
        match (inverse(self.cov), inverse(theirs.cov)) {
            (Some(a), Some(b)) => match (a + b).try_inverse() {
                // Symmetric by construction: average away rounding.
                Some(c) => PlaneUncertainty { cov: ((c + c.transpose()) / 2.0).into(), ..*self },
                None => *self,
            },
            _ => *self,
        }
    }

    /// The covariance of the plane's 4 coefficients (normal x, y, z, offset) of
    /// `normal . p + offset = 0`, row-major: what planners get. A point x's distance to the
    /// plane then has variance [x 1] C [x 1]^T.
    pub fn coefficient_covariance(&self) -> [f64; 16] {
        let (e1, e2) = (Vector3::from(self.axes[0]), Vector3::from(self.axes[1]));
        let c = Vector3::from(self.centre);
        // d(normal) = a1 e1 + a2 e2; d(offset) = -(a1 e1 + a2 e2) . c - shift.
        let j =
            nalgebra::Matrix4x3::new(e1.x, e2.x, 0.0, e1.y, e2.y, 0.0, e1.z, e2.z, 0.0, -e1.dot(&c), -e2.dot(&c), -1.0);
        let cov = j * Matrix3::from(self.cov).transpose() * j.transpose();
        let mut out = [0.0; 16];
        for r in 0..4 {
            for k in 0..4 {
                out[4 * r + k] = cov[(r, k)];
            }
        }
        out
    }

    /// The uncertainty about `centre` and in-plane `axes` whose coefficient covariance is
    /// `c` (as `coefficient_covariance` gives it): a = e . dn and shift = -(dn . centre + dd)
    /// taken of the coefficients' errors (dn, dd).
    pub fn from_coefficient_covariance(c: &[f64; 16], centre: [f64; 3], axes: [[f64; 3]; 2]) -> PlaneUncertainty {
        let (e1, e2, x) = (Vector3::from(axes[0]), Vector3::from(axes[1]), Vector3::from(centre));
        let j = nalgebra::Matrix3x4::new(e1.x, e1.y, e1.z, 0.0, e2.x, e2.y, e2.z, 0.0, -x.x, -x.y, -x.z, -1.0);
        let cov = j * nalgebra::Matrix4::from_row_slice(c) * j.transpose();
        PlaneUncertainty { centre, axes, cov: ((cov + cov.transpose()) / 2.0).into() }
    }

    /// The variance of the plane's position along its normal, averaged over a surface
    /// around `centre` whose points lie `lever_sq` m^2 from it on average: the shift's
    /// variance plus the tilts' times their lever arm.
    pub fn mean_offset_variance(&self, lever_sq: f64) -> f64 {
        let [[a, _, _], [_, d, _], [_, _, s]] = self.cov;
        // Averaged over every direction in the plane, a tilt's lever arm squared is half
        // the mean squared distance.
        s + (a + d) / 2.0 * lever_sq
    }

    /// The same uncertainty seen in another frame (`rotate` then `translate`).
    pub fn moved(&self, rotate: impl Fn([f64; 3]) -> [f64; 3], translate: impl Fn([f64; 3]) -> [f64; 3]) -> Self {
        PlaneUncertainty { centre: translate(self.centre), axes: self.axes.map(rotate), cov: self.cov }
    }

    /// The same with a systematic tilt `lean` (rad, along `axes`) counted as an error of its
    /// own: a fit that may lean is known no better than its lean.
    pub fn with_lean(&self, lean: [f64; 2]) -> PlaneUncertainty {
        let mut cov = self.cov;
        for (r, br) in lean.iter().enumerate() {
            for (k, bk) in lean.iter().enumerate() {
                cov[r][k] += br * bk;
            }
        }
        PlaneUncertainty { cov, ..*self }
    }
}

/// Whether a foot may trust a polygon's plane, and if not, why: [`footing`]'s verdict, the
/// one rule for the frame's polygons and the map's.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Footing {
    Steppable,
    /// Its tilt is not known to `STEPPABLE_TILT_DEG` at 95 %: its noise, or the lean a
    /// support narrow in one direction gives its fit, is too large.
    TiltUnknown,
    /// No frame saw it with `MIN_STEPPABLE_PIXELS` pixels.
    FewPixels,
}

impl Footing {
    pub fn is_steppable(self) -> bool {
        self == Footing::Steppable
    }

    /// What a polygon read without a verdict is taken as: not steppable until a frame
    /// shows it is.
    pub fn unknown() -> Footing {
        Footing::TiltUnknown
    }
}

/// A steppable plane's tilt is known to this at 95 % (1.96 sigma along its worst axis).
pub const STEPPABLE_TILT_DEG: f64 = 1.0;

/// A steppable plane was seen whole by at least this many pixels in one frame. A region's
/// outline pixels mix it with its neighbours; in a small one they are a large share (4 /
/// sqrt(N): 28 % at 200), and they lean its fit more than its noise does, which its
/// covariance does not see (far patches of 100 to 150 pixels leaned twice their 1.96 sigma).
pub const MIN_STEPPABLE_PIXELS: usize = 200;

/// The rule for what is published as steppable: a plane whose tilt is known to
/// `STEPPABLE_TILT_DEG` at 95 % (by its covariance, which counts the leans its noise does
/// not show: `noise_lean`, and a bend between its halves), seen by at least `MIN_STEPPABLE_PIXELS` pixels in one frame. A
/// plane of unknown uncertainty (a hand-made polygon, not measured) is taken as given.
pub fn footing(u: &PlaneUncertainty, most_pixels: usize) -> Footing {
    if !u.is_known() {
        Footing::Steppable
    } else if most_pixels < MIN_STEPPABLE_PIXELS {
        Footing::FewPixels
    } else if 1.96 * u.tilt_sigma_rad() > STEPPABLE_TILT_DEG.to_radians() {
        Footing::TiltUnknown
    } else {
        Footing::Steppable
    }
}

/// The variance of the across-plane noise of a point `p` (camera frame) whose dot product
/// with the plane's unit normal is `np`, up to the sensor's scale (see the module's doc):
/// (0.5 + 0.5 r)^2 cos. In f32: a weight needs no more, and its root and division in f32
/// cost a fraction of f64's, which bounded the vector passes.
#[inline(always)]
fn relative_variance(p: &[f32; 3], np: f32) -> f32 {
    let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
    let cos = (np.abs() / r).max(0.05);
    let spread = 0.5 + 0.5 * r;
    spread * spread * cos
}

/// Two unit axes at right angles in the plane of the unit normal `n`: any in-plane axis,
/// and the one across it; None for a normal too short to have a plane. A plane's
/// covariance is stored on these axes, and read back on them (map snapshots).
pub fn in_plane_axes(n: &Vector3<f64>) -> Option<[Vector3<f64>; 2]> {
    let helper = if n.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let e1 = n.cross(&helper).try_normalize(1e-9)?;
    Some([e1, n.cross(&e1)])
}

/// The uncertainty of `fit` from the points within `dist` of its plane, and where
/// `halves_agreement` cuts those inliers; None with too few of them to fix a plane (fewer
/// than 4, or all on a line). `points` are every `stride`-th of the plane's points (1: all
/// of them; a region's `PointSample`), each standing for `stride`: its pixels lie on a
/// regular grid, so the sums of every k-th point times k are those of all, to well under a
/// percent, at the same cost for any size.
pub fn plane_uncertainty(
    points: &[[f32; 3]],
    stride: usize,
    fit: &PlaneFit,
    dist: f64,
) -> Option<(PlaneUncertainty, HalvesCut)> {
    let n = fit.normal;
    let [e1, e2] = in_plane_axes(&n)?;
    // One pass: a_i = (x, y, -1) with x, y the lever arms along e1, e2, taken from the
    // plane's foot of the camera for now and moved to the inliers' centroid after; H and
    // M from sums of x^2, xy, y^2, x, y, 1, plain and weighted by each point's g^2.
    let foot = -n * fit.offset;
    let frame = FitFrame { n: n.into(), offset: fit.offset, foot: foot.into(), axes: [e1.into(), e2.into()], dist };
    let sums = frame.inlier_sums(points);
    let (h, m, count, sum) = (sums.plain, sums.weighted, sums.count as usize, Vector3::from(sums.sum));
    if count < 4 {
        return None;
    }
    let c = sum / count as f64;
    // Lever arms from the centroid: x' = x - cx, so sum x'^2 = sum x^2 - 2 cx sum x + cx^2 sum 1.
    let (cx, cy) = ((c - foot).dot(&e1), (c - foot).dot(&e2));
    let centred = |s: [f64; 6]| {
        let (sx, sy, s1) = (s[3] - cx * s[5], s[4] - cy * s[5], s[5]);
        let sxx = s[0] - 2.0 * cx * s[3] + cx * cx * s[5];
        let sxy = s[1] - cx * s[4] - cy * s[3] + cx * cy * s[5];
        let syy = s[2] - 2.0 * cy * s[4] + cy * cy * s[5];
        Matrix3::new(sxx, sxy, -sx, sxy, syy, -sy, -sx, -sy, s1) * stride as f64
    };
    let (h, m) = (centred(h), centred(m));
    // Three parameters fitted: the residuals' weighted variance has N - 3 degrees of freedom.
    let scale = sums.scale / (count - 3) as f64;
    // Points on a line leave a tilt free: no covariance worth the name.
    if !(SymmetricEigen::new(h).eigenvalues.min() > 1e-12 * h.trace()) {
        return None;
    }
    let h_inv = h.try_inverse()?;
    let cov = h_inv * m * h_inv * scale;
    if !cov.iter().all(|v| v.is_finite()) {
        return None;
    }
    // H's top left is the inliers' spread in the plane about their centroid: its smaller
    // eigenvector is the direction they are narrowest along.
    let spread = SymmetricEigen::new(h.fixed_view::<2, 2>(0, 0).into_owned());
    let narrow = spread.eigenvectors.column(spread.eigenvalues.imin());
    let cut = HalvesCut { centre: c, across: e1 * narrow[0] + e2 * narrow[1] };
    let row = |k: usize| [cov[(k, 0)], cov[(k, 1)], cov[(k, 2)]];
    Some((PlaneUncertainty { centre: c.into(), axes: [e1.into(), e2.into()], cov: [row(0), row(1), row(2)] }, cut))
}

/// The tilt (rad, along `u.axes`) that the least-squares fit of `fit`'s inliers is expected
/// to have from the sensor's noise alone. A pixel's noise runs along its ray, partly along
/// the plane; across a support that is narrow in one direction that part rivals the
/// surface's own spread, and the fitted normal leans towards the rays (errors in
/// variables). To first order the normal moves by -A^-1 b: A the inliers' spread in the
/// plane, b the rays' noise covariance between the plane's axes and its normal, at the
/// noise scale of the fit's residuals (the module's model). `u` is `plane_uncertainty` of
/// the same points and fit: its centre and axes. A ratio of sums over a grid of pixels: a
/// spread-out `NOISE_LEAN_POINTS` of them give it as well as all.
pub fn noise_lean(points: &[[f32; 3]], fit: &PlaneFit, dist: f64, u: &PlaneUncertainty) -> [f64; 2] {
    let (n, c, [e1, e2]) = (fit.normal, Vector3::from(u.centre), u.axes.map(Vector3::from));
    let (mut count, mut scale, mut spread, mut lean) = (0.0, 0.0, Matrix2::zeros(), Vector2::zeros());
    for p32 in points.iter().step_by(points.len().div_ceil(NOISE_LEAN_POINTS).max(1)) {
        let p = Vector3::new(p32[0] as f64, p32[1] as f64, p32[2] as f64);
        let np = n.dot(&p);
        let r = np + fit.offset;
        if r.abs() >= dist {
            continue;
        }
        let g2 = relative_variance(p32, np as f32) as f64;
        let xy = Vector2::new((p - c).dot(&e1), (p - c).dot(&e2));
        let ray = p / p.norm();
        // Along the ray the variance is g^2 / cos^2; its covariance between an in-plane
        // axis and the normal is that times (ray . e)(ray . n), cos = |ray . n|.
        let cos = ray.dot(&n).abs().max(0.05);
        count += 1.0;
        scale += r * r / g2;
        spread += xy * xy.transpose();
        lean += Vector2::new(ray.dot(&e1), ray.dot(&e2)) * (g2 * ray.dot(&n).signum() / cos);
    }
    if count < 4.0 {
        return [0.0; 2];
    }
    let scale = scale / (count - 3.0);
    match spread.try_inverse() {
        Some(inv) => (-(inv * lean) * scale).into(),
        None => [0.0; 2],
    }
}

/// At most about this many of a plane's points go into `noise_lean`.
const NOISE_LEAN_POINTS: usize = 512;

/// A fitted plane as `plane_uncertainty` takes its inliers' sums: the inlier distance, and
/// lever arms x, y along `axes` from `foot` (the plane's foot of the camera).
#[derive(Clone, Copy, Debug)]
struct FitFrame {
    n: [f64; 3],
    offset: f64,
    foot: [f64; 3],
    axes: [[f64; 3]; 2],
    dist: f64,
}

/// The inliers' sums: how many, the sum of their points, of r^2 / g^2 (r the residual, g^2
/// the point's relative variance), and of x^2, xy, y^2, x, y, 1, plain and weighted by g^2.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct InlierSums {
    count: f64,
    sum: [f64; 3],
    scale: f64,
    plain: [f64; 6],
    weighted: [f64; 6],
}

impl FitFrame {
    /// The sums over the points: eight at a time in AVX-512, four in AVX2 or NEON, the last
    /// ones (and all, at the baseline) by `inlier_sums_scalar`, the vector passes' oracle.
    fn inlier_sums(&self, points: &[[f32; 3]]) -> InlierSums {
        let level = level();
        let step = match level {
            Level::Avx512 => 8,
            Level::Avx2 | Level::Neon => 4,
            Level::Baseline => return self.inlier_sums_scalar(points),
        };
        let (full, rest) = points.split_at(points.len() / step * step);
        // SAFETY: each pass runs only at a level the CPU has (`level()`).
        let fast = match level {
            #[cfg(target_arch = "x86_64")]
            Level::Avx512 => unsafe { avx512::inlier_sums(self, full) },
            #[cfg(target_arch = "x86_64")]
            Level::Avx2 => unsafe { avx2::inlier_sums(self, full) },
            #[cfg(target_arch = "aarch64")]
            Level::Neon => unsafe { neon::inlier_sums(self, full) },
            _ => InlierSums::default(),
        };
        fast.plus(&self.inlier_sums_scalar(rest))
    }

    fn inlier_sums_scalar(&self, points: &[[f32; 3]]) -> InlierSums {
        let (n, foot, [e1, e2]) = (Vector3::from(self.n), Vector3::from(self.foot), self.axes.map(Vector3::from));
        let mut s = InlierSums::default();
        for p32 in points {
            let p = Vector3::new(p32[0] as f64, p32[1] as f64, p32[2] as f64);
            let np = n.dot(&p);
            let r = np + self.offset;
            if r.abs() >= self.dist {
                continue;
            }
            let (x, y) = ((p - foot).dot(&e1), (p - foot).dot(&e2));
            let g2 = relative_variance(p32, np as f32);
            s.scale += r * r * (1.0 / g2) as f64;
            s.count += 1.0;
            s.sum = (Vector3::from(s.sum) + p).into();
            let terms = [x * x, x * y, y * y, x, y, 1.0];
            for k in 0..6 {
                s.plain[k] += terms[k];
                s.weighted[k] += terms[k] * g2 as f64;
            }
        }
        s
    }
}

impl InlierSums {
    fn plus(&self, o: &InlierSums) -> InlierSums {
        InlierSums {
            count: self.count + o.count,
            sum: std::array::from_fn(|k| self.sum[k] + o.sum[k]),
            scale: self.scale + o.scale,
            plain: std::array::from_fn(|k| self.plain[k] + o.plain[k]),
            weighted: std::array::from_fn(|k| self.weighted[k] + o.weighted[k]),
        }
    }
}

/// How two halves of a plane's inliers agree, when cut across their narrowest in-plane
/// direction: the angle between the planes fitted to each half, and the standard deviation
/// that angle has when both halves are one plane with noise (their tilt sigmas combined).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalvesAgreement {
    pub angle_rad: f64,
    pub sigma_rad: f64,
}

impl HalvesAgreement {
    /// Whether the halves are one surface: their angle within 3 sigma of noise, or under
    /// `floor_rad` (a bend that small tilts the whole plane by less than the bar).
    pub fn one_surface(&self, floor_rad: f64) -> bool {
        self.angle_rad <= (3.0 * self.sigma_rad).max(floor_rad)
    }

    /// How much more than their noise's 3 sigma the halves bend, rad (0 when they do not).
    pub fn bend_beyond_noise_rad(&self) -> f64 {
        (self.angle_rad - 3.0 * self.sigma_rad).max(0.0)
    }
}

/// Where a plane's inliers are cut in two: through their centroid, across the in-plane
/// direction they spread least along (a unit vector). `plane_uncertainty` finds it from
/// the sums it takes anyway.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HalvesCut {
    pub centre: Vector3<f64>,
    pub across: Vector3<f64>,
}

/// Cuts the inliers of `fit` in two at `cut` (from `plane_uncertainty` of the same points
/// and fit) and fits each half. The uncertainty of the whole fit assumes one plane plus
/// noise; a region that straddles a crease (a strip of tread seen at the image's edge,
/// with two rows of the riser below it) breaks that assumption, and its covariance is
/// then far too small: its halves disagree by many sigmas. None when a half has too few
/// points to fix a plane (the support is too narrow to test, or to trust). `points` are
/// every `stride`-th of the plane's points, each standing for `stride` (as in
/// `plane_uncertainty`): the halves' noise is that of all the points, not of the
/// sample's fewer.
pub fn halves_agreement(
    points: &[[f32; 3]],
    stride: usize,
    fit: &PlaneFit,
    dist: f64,
    cut: &HalvesCut,
) -> Option<HalvesAgreement> {
    let halves = split_halves(points, fit, dist, cut);
    let half = |pts: &[[f32; 3]]| {
        let f = super::cpu::ransac::refit(pts, fit.normal_f32(), fit.offset as f32, dist as f32)?;
        Some((f.normal, plane_uncertainty(pts, stride, &f, dist)?.0.tilt_sigma_rad()))
    };
    let ((na, sa), (nb, sb)) = (half(&halves[0])?, half(&halves[1])?);
    Some(HalvesAgreement { angle_rad: na.dot(&nb).clamp(-1.0, 1.0).acos(), sigma_rad: sa.hypot(sb) })
}

/// `fit`'s inliers (within `dist`, as `PlaneFit::distance` measures) on either side of
/// `cut`, each half in the points' order: on x86-64 with AVX-512 eight points at a time,
/// the rest (and all, elsewhere) by `split_halves_scalar`, its oracle.
fn split_halves(points: &[[f32; 3]], fit: &PlaneFit, dist: f64, cut: &HalvesCut) -> [Vec<[f32; 3]>; 2] {
    // Room for the vector pass's whole-register stores past the last point (16 floats).
    let mut halves = [Vec::with_capacity(points.len() + 6), Vec::with_capacity(points.len() + 6)];
    #[cfg(target_arch = "x86_64")]
    let rest = if level() == Level::Avx512 {
        let (full, rest) = points.split_at(points.len() / 8 * 8);
        // SAFETY: the CPU has AVX-512 (checked just above); both halves are empty with
        // room for every point and 6 more.
        unsafe { avx512::split_halves(full, fit, dist, cut, &mut halves) };
        rest
    } else {
        points
    };
    #[cfg(not(target_arch = "x86_64"))]
    let rest = points;
    split_halves_scalar(rest, fit, dist, cut, &mut halves);
    halves
}

/// `split_halves`, one point after another, appending to `halves`.
fn split_halves_scalar(
    points: &[[f32; 3]],
    fit: &PlaneFit,
    dist: f64,
    cut: &HalvesCut,
    halves: &mut [Vec<[f32; 3]>; 2],
) {
    for p in points.iter().filter(|p| fit.distance(p) < dist) {
        let q = Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        halves[usize::from((q - cut.centre).dot(&cut.across) >= 0.0)].push(*p);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of the plane through `centre` with unit normal `n`, over `[-w/2, w/2] x
    /// [-l/2, l/2]` along `(across, along)` on a grid, each moved along its ray from the
    /// origin by noise of `sigma` m at 1 m, growing as the module's model has it.
    fn seen_on_rays(
        n: Vector3<f64>,
        centre: Vector3<f64>,
        [across, along]: [Vector3<f64>; 2],
        [w, l]: [f64; 2],
        sigma: f64,
        rng: &mut impl rand::Rng,
    ) -> Vec<[f32; 3]> {
        use rand_distr::{Distribution, StandardNormal};
        let mut out = Vec::new();
        for i in 0..12 {
            for j in 0..150 {
                let p = centre + across * (w * (i as f64 / 11.0 - 0.5)) + along * (l * (j as f64 / 149.0 - 0.5));
                let (r, ray) = (p.norm(), p.normalize());
                let cos = ray.dot(&n).abs();
                let e: f64 = StandardNormal.sample(rng);
                let q = p + ray * (e * sigma * (0.5 + 0.5 * r) / cos.sqrt());
                out.push([q.x as f32, q.y as f32, q.z as f32]);
            }
        }
        out
    }

    #[test]
    fn the_noise_lean_is_the_lean_of_fits_to_a_narrow_strip_seen_at_a_slant() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(13);
        // A floor 0.9 m below a camera looking ahead (y down, z ahead), 1.6 m ahead and 1 m
        // wide, at 3 mm of noise: the mean lean of 40 fits, and of their predictions.
        let n = Vector3::new(0.0, -1.0, 0.0);
        let dist = 0.03;
        let mut leans = |deep: f64| {
            let (mut leaned, mut predicted) = (Vector2::zeros(), Vector2::zeros());
            for _ in 0..40 {
                let extent = [deep, 1.0];
                let points =
                    seen_on_rays(n, Vector3::new(0.0, 0.9, 1.6), [Vector3::z(), Vector3::x()], extent, 0.003, &mut rng);
                let fit =
                    crate::extract::cpu::ransac::refit(&points, [0.0, -1.0, 0.0], 0.9, dist as f32).expect("a fit");
                let (u, _) = plane_uncertainty(&points, 1, &fit, dist).expect("an uncertainty");
                // The fit's normal less the true one, on the fit's own axes (each trial's own).
                let axes = u.axes.map(Vector3::from);
                leaned -= Vector2::new(n.dot(&axes[0]), n.dot(&axes[1])) / 40.0;
                predicted += Vector2::from(noise_lean(&points, &fit, dist, &u)) / 40.0;
            }
            (leaned, predicted)
        };
        // 4 cm deep along the view: the fits lean by about a degree, as predicted to a fifth.
        let (leaned, predicted) = leans(0.04);
        assert!(leaned.norm().to_degrees() > 0.5, "the strip's fits lean: {leaned:?}");
        assert!((leaned - predicted).norm() < 0.2 * leaned.norm(), "leaned {leaned:?}, predicted {predicted:?}");
        // 50 cm deep: under a tenth of that, either way.
        let (wide_leaned, wide_predicted) = leans(0.5);
        for l in [wide_leaned, wide_predicted] {
            assert!(l.norm() < 0.1 * leaned.norm(), "{l:?} against the strip's {leaned:?}");
        }
    }

    #[test]
    fn the_footing_rule_marks_what_is_not_known_to_a_degree_at_95_percent_or_seen_small() {
        let sigma_deg = |deg: f64| {
            let s = deg.to_radians().powi(2);
            PlaneUncertainty {
                centre: [0.0, 0.0, 1.0],
                axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
                cov: [[s, 0.0, 0.0], [0.0, s / 4.0, 0.0], [0.0, 0.0, 1e-6]],
            }
        };
        let bar = STEPPABLE_TILT_DEG / 1.96;
        assert_eq!(footing(&sigma_deg(0.99 * bar), 5000), Footing::Steppable);
        assert_eq!(footing(&sigma_deg(1.01 * bar), 5000), Footing::TiltUnknown);
        assert_eq!(footing(&sigma_deg(0.1), MIN_STEPPABLE_PIXELS), Footing::Steppable);
        assert_eq!(footing(&sigma_deg(0.1), MIN_STEPPABLE_PIXELS - 1), Footing::FewPixels);
        // A lean counts as much as noise of its size, along its axis.
        let lean = (0.9 * bar).to_radians();
        assert_eq!(footing(&sigma_deg(0.6 * bar).with_lean([lean, 0.0]), 5000), Footing::TiltUnknown);
        assert_eq!(footing(&sigma_deg(0.6 * bar).with_lean([0.0, lean]), 5000), Footing::Steppable);
        // Hand-made planes (no covariance) are taken as given.
        assert_eq!(footing(&PlaneUncertainty::default(), 0), Footing::Steppable);
    }

    #[test]
    fn fast_halves_split_is_the_scalar_one() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        let n = Vector3::new(0.1, -0.75, -0.62).normalize();
        let [e1, e2] = in_plane_axes(&n).expect("a unit normal");
        let fit = PlaneFit { normal: n, offset: 1.4, inliers: 0, points: 0, rms: 0.0 };
        let foot = -n * fit.offset;
        // The centre a point in f32, so that a point can lie exactly on the cut.
        let centre = (foot + e1 * 0.1).map(|c| c as f32 as f64);
        let cut = HalvesCut { centre, across: (e1 + e2 * 0.3).normalize() };
        for size in [0usize, 7, 8, 9, 16, 1001, 2048] {
            // Within 3 mm of the plane, every third point 5 cm off it, and every 50th on
            // the cut's centre (on the cut: the upper half).
            let points: Vec<[f32; 3]> = (0..size)
                .map(|i| {
                    let off = if i % 3 == 1 { 0.05 } else { rng.random_range(-0.003..0.003) };
                    let p = if i % 50 == 7 {
                        cut.centre
                    } else {
                        foot + e1 * rng.random_range(-0.8..0.8) + e2 * rng.random_range(-0.8..0.8) + n * off
                    };
                    [p.x as f32, p.y as f32, p.z as f32]
                })
                .collect();
            let mut slow = [Vec::new(), Vec::new()];
            split_halves_scalar(&points, &fit, 0.01, &cut, &mut slow);
            assert_eq!(split_halves(&points, &fit, 0.01, &cut), slow, "size {size}");
            if size > 1000 {
                assert!(slow.iter().all(|h| h.len() > size / 5), "size {size}: both halves hold points");
                assert!(slow[0].len() + slow[1].len() < size * 3 / 4, "size {size}: outliers left out");
            }
        }
    }

    #[test]
    fn fast_inlier_sums_are_the_scalar_ones() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let n = Vector3::new(0.1, -0.75, -0.62).normalize();
        let (offset, dist) = (1.4, 0.01);
        let [e1, e2] = in_plane_axes(&n).expect("a unit normal");
        let frame = FitFrame { n: n.into(), offset, foot: (-n * offset).into(), axes: [e1.into(), e2.into()], dist };
        for size in [0usize, 3, 4, 9, 1000, 1001, 1003, 20_002] {
            // On the plane within 3 mm, every fourth point 5 cm off it.
            let points: Vec<[f32; 3]> = (0..size)
                .map(|i| {
                    let off = if i % 4 == 1 { 0.05 } else { rng.random_range(-0.003..0.003) };
                    let p = -n * offset + e1 * rng.random_range(-0.8..0.8) + e2 * rng.random_range(-0.8..0.8) + n * off;
                    [p.x as f32, p.y as f32, p.z as f32]
                })
                .collect();
            let (fast, slow) = (frame.inlier_sums(&points), frame.inlier_sums_scalar(&points));
            assert_eq!(fast.count, slow.count, "size {size}: the same inliers");
            let all = |s: &InlierSums| [&s.sum[..], &[s.scale], &s.plain, &s.weighted].concat();
            for (a, b) in all(&fast).iter().zip(all(&slow)) {
                assert!((a - b).abs() <= 1e-12 * (1.0 + b.abs()), "size {size}: {a} vs {b}");
            }
            assert!(
                size < 100 || (slow.count > 0.6 * size as f64 && slow.count < 0.9 * size as f64),
                "outliers left out"
            );
        }
    }
}
