//! Registration of the video to the CT model (issue 16): each frame's 6-DoF pose refined by
//! direct photometric alignment against the model (texture x calibrated light), coarse to fine,
//! and the video's continuity as a prior.
//!
//! ```text
//! ModelParts (scene, UVs, texture, light, camera) ─ FrameRegistrar ─ refine_frame(frame, pose)
//!                                                                  └ refine_video(frames, poses)
//! ModelParts + first pose ─ Tracker ─ track(frames) (no tracker: `--poses first`)
//! ```

pub mod accuracy;
pub mod align;
pub mod blocks;
pub mod blur;
pub mod chroma;
pub mod consensus;
pub mod frame;
pub mod joint;
pub mod joint_shift;
pub mod level;
pub mod light;
pub mod photometric;
pub mod pose;
pub mod prior;
pub mod pyramid;
pub mod rounds;
pub mod track;
pub mod video;

pub use frame::{FrameObs, FrameRegistrar, FrameRegistration, FrameStatus, RegistrationOptions};
pub use photometric::{ModelParts, PhotometricModel};
pub use pose::{apply_delta, delta_between, pose_error, pose_error_axes, PoseDelta};
pub use rounds::{register_round, RoundKind, RoundOptions};
pub use track::{interpolate_flagged, TrackOptions, TrackState, Tracker};
pub use video::{refine_video, VideoOptions, VideoRegistration};
