//! Files in and out: mesh files (STL, PLY, OBJ), X-ray DICOM files, JSON read with the failing
//! field named, and atomic writes, so that a failed run never
//! leaves a half-written file or folder behind.

mod atomic;
mod dicom;
mod json;
mod mesh_file;
mod shown;

pub use atomic::{check_writable, fill_dir_atomically, out_in_use, write_atomic};
pub use dicom::{
    is_dicom, read_dicom_geometry, read_dicom_image, write_dicom_xray, DicomError, DicomGeometry,
    DicomXray, SpacingTag,
};
pub use json::parse_json;
pub use mesh_file::{
    read_mesh, write_mesh, write_obj, write_ply, write_ply_with, write_stl_ascii, write_stl_binary,
    MeshIoError, Rgb,
};
pub use shown::{printable, shown};

/// An X-ray for drawing: a DICOM file's pixels (`read_dicom_image`) or a PNG or JPEG.
pub fn read_xray_image(path: &std::path::Path) -> Result<image::DynamicImage, String> {
    if is_dicom(path) {
        // The caller names the file; a DICOM error names it too, so it is said once.
        read_dicom_image(path)
            .map(image::DynamicImage::ImageLuma8)
            .map_err(|e| {
                let e = e.to_string();
                match e.strip_prefix(&format!("{}: ", path.display())) {
                    Some(reason) => reason.to_string(),
                    None => e,
                }
            })
    } else {
        image::open(path).map_err(|e| e.to_string())
    }
}
