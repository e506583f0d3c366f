//! The commands a person runs, each a whole job from input folder to output folder:
//! they chain the stages and write results atomically. `main.rs` only parses and calls these.

pub mod build;
pub mod convert;
pub mod demo;
pub mod flythrough;
pub mod new_views_figure;
pub mod progress;
pub mod register;
pub mod registration_overlays;
pub mod render;
pub mod report;
pub mod segment;
pub(crate) mod selection_report;
pub mod summary;
pub mod truth_eval;
