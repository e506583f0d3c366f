//! The library's error type. File errors name the file and what is wrong with it; every other
//! layer has its own typed error (shading fits, geometry, images, the build), wrapped here, so
//! that a message names what failed and a caller can match on what went wrong.

use std::path::{Path, PathBuf};

/// `Result` with bronchosim's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// What went wrong, with the file it concerns. Messages are one line and say what was expected.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system error while reading or writing `path`.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file exists but its content is not what the format requires.
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// The input is valid but uses a feature bronchosim does not support.
    #[error("{path}: unsupported: {message}")]
    Unsupported { path: PathBuf, message: String },
    /// A required file or folder is missing.
    #[error("{path}: not found ({what})")]
    Missing { path: PathBuf, what: String },
    /// An image operation (sizes, remapping, encoding) that cannot be done.
    #[error(transparent)]
    Image(#[from] crate::image::ImageError),
    /// A volume operation (segmentation, marching cubes, a path) that cannot be done.
    #[error(transparent)]
    Volume(#[from] crate::volume::VolumeError),
    /// A surface operation (mesh, ray-casting scene, texture atlas) that cannot be done.
    #[error(transparent)]
    Geometry(#[from] crate::mesh::GeometryError),
    /// A shading model that cannot be fitted or used as asked.
    #[error(transparent)]
    Shading(#[from] crate::shading::ShadingError),
    /// A build that cannot go on with these frames.
    #[error(transparent)]
    Build(#[from] crate::workflow::build::BuildError),
    /// Options out of their range.
    #[error("{stage}: {message}")]
    BadOptions {
        /// Which command or stage.
        stage: &'static str,
        /// What is wrong.
        message: String,
    },
    /// An error that concerns no single file and no layer's typed error.
    #[error("{0}")]
    Other(String),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl AsRef<Path>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.as_ref().to_path_buf(),
            source,
        }
    }

    /// Invalid content in `path`.
    pub fn invalid(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error::Invalid {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    /// An unsupported feature in `path`.
    pub fn unsupported(path: impl AsRef<Path>, message: impl Into<String>) -> Self {
        Error::Unsupported {
            path: path.as_ref().to_path_buf(),
            message: message.into(),
        }
    }

    /// A missing file or folder.
    pub fn missing(path: impl AsRef<Path>, what: impl Into<String>) -> Self {
        Error::Missing {
            path: path.as_ref().to_path_buf(),
            what: what.into(),
        }
    }
}
