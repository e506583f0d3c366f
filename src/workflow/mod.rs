//! The commands a person runs, each a whole job from input folder to output folder:
//! they chain the stages and write results atomically. `main.rs` only parses and calls these.

pub mod albedo_truth;
pub mod build;
pub mod build_frames;
pub mod convert;
pub mod cross_validate;
pub mod demo;
pub mod flythrough;
pub mod gain_refine;
pub mod light_refine;
pub mod new_views_figure;
pub mod progress;
pub mod render;
pub mod report;
pub mod segment;
pub mod shading_truth;
pub mod truth_eval;
