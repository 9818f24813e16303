//! The loop's messages between frames (`docs/design.md` §2.4, §6): setpoints
//! and plant states travel in the tracker's frame, the frame a lab's task
//! and tracker share; the controller (host or the chip's bridge) and the
//! planner's learning work in the model's base frame, the frame the net was
//! trained in. Each side maps at its edge with its own robot file's `[base]`:
//! the planner and the controller with the model's, the plant with the real
//! robot's. Without `[base]` every map is the identity and leaves every bit.

use tendril_shared::messages::{setpoint_flags, PlantState, Setpoint};

use crate::robot::RigidMap;

fn f64s<const N: usize>(v: [f32; N]) -> [f64; N] {
    v.map(f64::from)
}

fn f32s<const N: usize>(v: [f64; N]) -> [f32; N] {
    v.map(|x| x as f32)
}

/// `s` mapped by `map`: the pose, its velocity and tangent columns (the
/// pose's derivatives), the tangent's axes, and a dynamic offset given along
/// x, y, z (one along the tangent's axes moves with them).
pub fn setpoint(map: &RigidMap, s: &Setpoint) -> Setpoint {
    if map.is_identity() {
        return *s;
    }
    let mut out = *s;
    let dim = (s.tangent_dim as usize).min(3);
    let has_tangent = s.flags & setpoint_flags::HAS_TANGENT != 0 && dim > 0;
    let mut derivatives = [[0.0f64; 7]; 4];
    derivatives[0] = f64s(s.velocity);
    for (d, column) in derivatives[1..].iter_mut().zip(&s.tangent).take(dim) {
        *d = f64s(*column);
    }
    let n = if has_tangent { 1 + dim } else { 1 };
    out.pose = f32s(map.pose_with_derivatives(f64s(s.pose), &mut derivatives[..n]));
    out.velocity = f32s(derivatives[0]);
    if has_tangent {
        for (column, d) in out.tangent.iter_mut().zip(&derivatives[1..n]) {
            *column = f32s(*d);
        }
        for axis in out.tangent_axes.iter_mut().take(dim) {
            *axis = f32s(map.direction(f64s(*axis)));
        }
    } else {
        out.dynamic_offset = f32s(map.direction(f64s(s.dynamic_offset)));
    }
    out
}

/// `s` with its tracker frame's tip pose mapped by `map` (a state without a
/// frame yet, `tip_seq` 0, keeps its zeros).
pub fn state(map: &RigidMap, s: &PlantState) -> PlantState {
    if map.is_identity() || s.tip_seq == 0 {
        return *s;
    }
    let mut out = *s;
    out.tip_pose = f32s(map.pose(f64s(s.tip_pose)));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::robot::BasePose;

    const BASE: BasePose = BasePose {
        translation: [0.3, -0.2, 0.05],
        rotation: [0.1, 0.4, -1.2],
    };

    fn a_setpoint() -> Setpoint {
        let s = std::f32::consts::FRAC_1_SQRT_2;
        Setpoint {
            pose: [0.01, 0.02, 0.38, s, 0.0, s, 0.0],
            velocity: [0.1, -0.2, 0.0, 0.01, 0.0, -0.01, 0.0],
            tangent: [
                [1.0, 0.0, 0.1, 0.0, 0.5, 0.0, 0.0],
                [0.0, 1.0, 0.2, 0.0, 0.0, 0.5, 0.0],
                [0.0; 7],
            ],
            tangent_axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0; 3]],
            tangent_dim: 2,
            flags: setpoint_flags::HAS_TANGENT | setpoint_flags::HAS_DYNAMIC_OFFSET,
            dynamic_offset: [0.001, -0.002, 0.0],
            ..Setpoint::default()
        }
    }

    fn close<const N: usize>(a: [f32; N], b: [f32; N]) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 2e-6)
    }

    #[test]
    fn a_setpoint_to_the_tracker_and_back_is_the_setpoint() {
        let s = a_setpoint();
        let there = setpoint(&BASE.to_tracker(), &s);
        assert!(!close(there.pose, s.pose), "the map moved nothing");
        let back = setpoint(&BASE.to_base(), &there);
        assert!(close(back.pose, s.pose) && close(back.velocity, s.velocity));
        for j in 0..2 {
            assert!(close(back.tangent[j], s.tangent[j]));
            assert!(close(back.tangent_axes[j], s.tangent_axes[j]));
        }
        assert_eq!(back.tangent[2], [0.0; 7]);
        // Along the tangent's axes the offset does not change.
        assert_eq!(there.dynamic_offset, s.dynamic_offset);
    }

    /// The controller's command pose moves by Σ d_j tangent_j: mapped to the
    /// tracker and back, or moved in the tracker's frame and mapped back,
    /// the same point (the offset means the same displacement in both).
    #[test]
    fn a_dynamic_offset_means_the_same_displacement_in_either_frame() {
        let mut s = a_setpoint();
        s.flags = setpoint_flags::HAS_DYNAMIC_OFFSET;
        let there = setpoint(&BASE.to_tracker(), &s);
        let moved =
            |s: &Setpoint| std::array::from_fn::<f32, 3, _>(|k| s.pose[k] + s.dynamic_offset[k]);
        let expect = BASE.to_tracker().point(f64s(moved(&s)));
        assert!(close(moved(&there), f32s(expect)));
    }

    #[test]
    fn a_state_without_a_frame_keeps_its_zeros_and_one_with_a_frame_moves() {
        let empty = PlantState::default();
        assert_eq!(state(&BASE.to_base(), &empty), empty);
        let seen = PlantState {
            tip_seq: 3,
            tip_pose: [0.01, 0.0, 0.39, 1.0, 0.0, 0.0, 0.0],
            ..PlantState::default()
        };
        let mapped = state(&BASE.to_base(), &seen);
        let expect = BASE.to_base().pose(f64s(seen.tip_pose));
        assert!(close(mapped.tip_pose, f32s(expect)));
        assert_eq!(state(&RigidMap::identity(), &seen), seen);
    }
}
