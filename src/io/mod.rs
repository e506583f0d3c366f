//! Readers and writers of the case format (CASE_FORMAT.md) and of the model folder.

pub mod atomic;
pub mod camera_file;
mod camera_opencv;
pub mod case;
pub mod case_untracked;
pub mod ct;
pub mod dicom;
pub mod frame_source;
pub mod glb_import;
pub mod glb_light;
pub mod image_mask;
pub mod mesh_export;
pub mod nifti;
pub mod output_dir;
pub mod paths;
pub mod png;
pub mod poses;
pub mod scope_light;
pub mod video;
