//! Fuzz the camera file parsers (camera.json, OpenCV FileStorage YAML and XML): Ok or Err,
//! never a panic or a hang. Byte 0 picks the format (0 JSON, 1 YAML, 2 XML, modulo 3); the
//! rest is the file's text.
#![no_main]

use bronchosim::io::camera_file::{parse_camera_str, CameraFormat};
use libfuzzer_sys::fuzz_target;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else {
        return;
    };
    let Ok(text) = std::str::from_utf8(rest) else {
        return;
    };
    let (format, name) = match which % 3 {
        0 => (CameraFormat::Json, "camera.json"),
        1 => (CameraFormat::Yaml, "camera.yml"),
        _ => (CameraFormat::Xml, "camera.xml"),
    };
    if let Ok(camera) = parse_camera_str(text, format, Path::new(name)) {
        // A camera that parsed must have passed validation.
        assert!(camera.validate().is_ok(), "{camera:?}");
    }
});
