//! A view's X-ray image as a case file names it: read now (its header only), so a bad image fails
//! before any work is done, and its size and DICOM geometry handed to the view's camera.

use super::{field_err, CaseError};
use std::path::{Path, PathBuf};

/// A view's image as the case names it: where it is, its size, and its DICOM geometry.
pub(super) struct ViewImage {
    /// Where the image is.
    pub path: PathBuf,
    /// Its width and height, pixels.
    pub size: (u32, u32),
    /// What its DICOM tags say, when it is a DICOM file.
    pub dicom: Option<crate::io::DicomGeometry>,
}

/// Read the image's header now, so a bad image fails before any work is done.
pub(super) fn view_image(case: &Path, field: &str, full: &Path) -> Result<ViewImage, CaseError> {
    if !full.is_file() {
        return Err(field_err(
            case,
            field,
            full.display(),
            "image file not found or unreadable",
        ));
    }
    if crate::io::is_dicom(full) {
        let d = crate::io::read_dicom_geometry(full).map_err(|source| CaseError::Dicom {
            path: case.to_path_buf(),
            field: field.into(),
            source: Box::new(source),
        })?;
        return Ok(ViewImage {
            path: full.to_path_buf(),
            size: (d.columns, d.rows),
            dicom: Some(d),
        });
    }
    let size = image::image_dimensions(full).map_err(|e| {
        let hint = if full
            .extension()
            .is_some_and(|x| x.eq_ignore_ascii_case("dcm"))
        {
            " (and it is not a DICOM Part 10 file: no DICM after the 128-byte preamble)"
        } else {
            ""
        };
        field_err(
            case,
            field,
            full.display(),
            format!("cannot be decoded: {e}{hint}"),
        )
    })?;
    Ok(ViewImage {
        path: full.to_path_buf(),
        size,
        dicom: None,
    })
}
