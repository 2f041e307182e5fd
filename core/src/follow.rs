//! Following the object from frame to frame in raw sensor frames: the pose
//! found in the last frame says where to look and where to start.
//!
//! [`crate::locate`] searches a whole frame: the plane by RANSAC, every
//! cluster, each candidate registered from many starts (about 100 M
//! instructions on a Cortex-M4F for a 224 x 172 frame). Between two frames
//! of a stream an object moves little, so `Int8Model::follow` looks only in
//! a box about where the last pose put the object ([`near`]), takes the
//! plane the last frame found instead of searching for it, registers the
//! cluster in the box nearest where the object was ([`centre`]; the box
//! may hold a neighbour too) by ICP from the last pose alone (no network,
//! no other start), and checks the pose against the frame as `locate`
//! does. A result that is not reliable (or an error: a cluster cut to too
//! few points) means the object moved too far, left the box, or is hidden:
//! locate it afresh.
//!
//! Limits: the plane is the last frame's, not searched again (a fixed
//! sensor; a moving one should locate now and then); the box replaces the
//! scene options' region of interest; a followed registration starts from
//! one pose only, so it reports no turn (keep the one the last `locate`
//! reported). Tested (the `scene` experiment): motions up to 2 cm and 5
//! degrees between frames, and streams turning 2 to 5 degrees a frame; the
//! box's margin allows more, ICP's reach may not.
//!
//! ```text
//! frame -> box about the last pose -> grid -> (last plane) -> clusters
//!       -> the nearest one's points -> ICP from the last pose -> verify
//! ```

use crate::format::Frame;
use crate::pose::Pose;
use crate::scene::{Plane, PlaneChoice, Region, SceneOptions};

/// The box's half-size is `1 + MARGIN` times the object's radius in each
/// axis of the sensor frame: room for the object to move half its radius
/// between two frames (7.5 cm for an object of 15 cm radius: 2.25 m/s at
/// 30 frames a second).
pub const MARGIN: f32 = 0.5;

/// The scene options for the frame after one where the object stood at
/// `previous` (sensor frame onto template, user units, as a registration
/// returns it): `scene` with its region of interest the box about where
/// `previous` puts the template's centre (`model.centre`), half-size
/// `(1 + MARGIN) radius`, and the plane `plane` when the last frame found
/// one (else `scene`'s choice).
pub fn near(
    scene: &SceneOptions,
    model: &Frame,
    previous: &Pose,
    plane: Option<Plane>,
    radius: f32,
) -> SceneOptions {
    let centre = centre(model, previous);
    let half = (1.0 + MARGIN) * radius;
    SceneOptions {
        roi: Some(Region {
            min: centre.map(|c| c - half),
            max: centre.map(|c| c + half),
        }),
        plane: plane.map_or(scene.plane, PlaneChoice::Given),
        ..*scene
    }
}

/// Where `previous` puts the template's centre (`model.centre`, the centre
/// of its user-unit frame) in the sensor frame.
pub fn centre(model: &Frame, previous: &Pose) -> [f32; 3] {
    previous.inverse().transform_point(model.centre)
}
