//! Camera paths: a humanoid walking up to the stairs and climbing them, the L515
//! at its waist looking down and ahead.

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use super::scene::{Scene, SceneKind, SpiralStair};

/// Height of the L515 above the ground under the feet, m.
pub const WAIST_HEIGHT: f64 = 0.95;
/// How far below the horizon the optical axis points, radians.
pub const PITCH_DOWN: f64 = 50.0 * std::f64::consts::PI / 180.0;
/// Length of one walking step, m (sets the sway's period).
const STEP_LENGTH: f64 = 0.3;

/// T_world_camera of a camera at `position` heading `yaw` (about world z, 0 = +x),
/// pitched down by `pitch` and rolled by `roll` about its optical axis.
pub fn camera_pose(position: Point3<f64>, yaw: f64, pitch: f64, roll: f64) -> Isometry3<f64> {
    let forward = Vector3::new(pitch.cos() * yaw.cos(), pitch.cos() * yaw.sin(), -pitch.sin());
    let right = Vector3::new(yaw.sin(), -yaw.cos(), 0.0);
    let down = forward.cross(&right);
    // Optical frame: x right, y down, z forward; then roll about z.
    let (s, c) = roll.sin_cos();
    let x = right * c + down * s;
    let y = down * c - right * s;
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, forward]));
    Isometry3::from_parts(Translation3::from(position.coords), UnitQuaternion::from_rotation_matrix(&rot))
}

/// Walking sway at `distance` along the path: the body shifts onto each foot in turn.
struct Sway {
    /// Sideways shift (to the left), m.
    lateral: f64,
    /// Vertical bob, m.
    bob: f64,
    roll: f64,
    yaw: f64,
}

fn sway(distance: f64) -> Sway {
    let side = (distance / STEP_LENGTH * std::f64::consts::PI).sin();
    Sway {
        lateral: 0.02 * side,
        bob: 0.012 * side.abs(),
        roll: 1.5f64.to_radians() * side,
        yaw: 1.0f64.to_radians() * side,
    }
}

/// Which way a walk goes over the scene's flight of steps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum Direction {
    #[default]
    Up,
    /// From the top (the landing, or the box scene's far end) back the way the walk up came.
    Down,
}

/// `frames` camera poses (T_world_camera) spaced evenly along the scene's walk up.
pub fn trajectory(scene: &Scene, frames: usize) -> Vec<Isometry3<f64>> {
    walk(scene, frames, Direction::Up)
}

/// `frames` camera poses spaced evenly along the scene's walk, up or down.
pub fn walk(scene: &Scene, frames: usize, direction: Direction) -> Vec<Isometry3<f64>> {
    let stair = scene.stair.as_ref().expect("every synthetic scene has a flight of steps");
    let (n, rise) = (stair.steps as f64, stair.rise);
    let down = direction == Direction::Down;
    // Walking down, the path runs the other way and the camera faces along it.
    let (back, turn) = if down { (std::f64::consts::PI, -1.0) } else { (0.0, 1.0) };
    (0..frames)
        .map(|i| {
            let s = if frames > 1 { i as f64 / (frames - 1) as f64 } else { 0.0 };
            match scene.kind {
                SceneKind::Straight => {
                    // Up: from 1.6 m before the first riser onto the third tread. Down: from
                    // 0.4 m onto the landing down to the second tread.
                    let (x0, x1) = if down {
                        ((n - 0.5) * stair.going + 0.4, 1.5 * stair.going)
                    } else {
                        (-1.6, 3.0 * stair.going)
                    };
                    let x = x0 + s * (x1 - x0);
                    let ground = rise * (x / stair.going + 0.5).clamp(0.0, n);
                    let w = sway((x - x0).abs());
                    let p = Point3::new(x, w.lateral, ground + WAIST_HEIGHT + w.bob);
                    camera_pose(p, back + w.yaw, PITCH_DOWN, w.roll)
                }
                SceneKind::Spiral => {
                    // On the walking line, up counter-clockwise from the floor seven steps;
                    // down the same way back.
                    let SpiralStair { step_angle, walk_radius, .. } = SpiralStair::default();
                    let (a0, a1) = (-60f64.to_radians(), 7.0 * step_angle);
                    let (a0, a1) = if down { (a1, a0) } else { (a0, a1) };
                    let a = a0 + s * (a1 - a0);
                    let ground = rise * (a / step_angle + 0.5).clamp(0.0, n);
                    let w = sway(walk_radius * (a - a0).abs());
                    // Heading along the tangent, turned a little towards the post to see the turn.
                    let heading = a + turn * (std::f64::consts::FRAC_PI_2 + 20f64.to_radians()) + w.yaw;
                    let r = walk_radius - w.lateral;
                    let p = Point3::new(r * a.cos(), r * a.sin(), ground + WAIST_HEIGHT + w.bob);
                    camera_pose(p, heading, PITCH_DOWN, w.roll)
                }
                SceneKind::Box => {
                    // Straight at the flight, passing the box on its left (down: back past it).
                    let (x0, x1) = if down { (0.6, -1.2) } else { (-1.2, 0.6) };
                    let x = x0 + s * (x1 - x0);
                    let w = sway((x - x0).abs());
                    camera_pose(Point3::new(x, w.lateral, WAIST_HEIGHT + w.bob), back + w.yaw, PITCH_DOWN, w.roll)
                }
            }
        })
        .collect()
}
