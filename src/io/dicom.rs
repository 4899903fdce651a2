//! X-ray DICOM files (DX or CR): the geometry a view's intrinsics follow from, the pixels for the
//! overlays, and a writer for the project's own phantom images.
//!
//! Focal length in pixels = source-to-detector distance (0018,1110) / pixel spacing, the spacing
//! taken from Imager Pixel Spacing (0018,1164) (at the detector) or else Pixel Spacing
//! (0028,0030). Source-to-patient distance (0018,1111), when present, gives the magnification at
//! the object (SID / SOD). A missing or contradictory tag is an error that names the file and
//! the tag.

use dicom_core::header::HasLength;
use dicom_core::value::{PrimitiveValue, C};
use dicom_core::{DataElement, Tag, VR};
use dicom_dictionary_std::{tags, uids};
use dicom_object::{FileMetaTableBuilder, InMemDicomObject};
use dicom_pixeldata::PixelDecoder;
use std::path::{Path, PathBuf};

/// A DICOM file cannot be used as an X-ray view.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DicomError {
    /// The file cannot be read or is not DICOM.
    #[error("{path}: not a readable DICOM file: {reason}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
    /// A tag the view needs is not in the file.
    #[error("{path}: DICOM tag {tag} is missing: {why}")]
    Missing {
        /// The file.
        path: PathBuf,
        /// The tag, by name and number.
        tag: String,
        /// What it is needed for.
        why: String,
    },
    /// A tag holds a value that cannot be right (or two tags disagree).
    #[error("{path}: DICOM tag {tag} = {value}: {reason}")]
    Tag {
        /// The file.
        path: PathBuf,
        /// The tag, by name and number.
        tag: String,
        /// Its value.
        value: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The file cannot be written.
    #[error("{path}: cannot write DICOM: {reason}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        reason: String,
    },
}

/// Where the pixel spacing was read from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum SpacingTag {
    /// Imager Pixel Spacing (0018,1164): at the detector.
    #[serde(rename = "ImagerPixelSpacing (0018,1164)")]
    Imager,
    /// Pixel Spacing (0028,0030): used when the imager's is absent.
    #[serde(rename = "PixelSpacing (0028,0030)")]
    Pixel,
}

impl SpacingTag {
    fn tag(self) -> Tag {
        match self {
            SpacingTag::Imager => tags::IMAGER_PIXEL_SPACING,
            SpacingTag::Pixel => tags::PIXEL_SPACING,
        }
    }

    fn label(self) -> &'static str {
        match self {
            SpacingTag::Imager => "ImagerPixelSpacing (0018,1164)",
            SpacingTag::Pixel => "PixelSpacing (0028,0030)",
        }
    }
}

const SID: &str = "DistanceSourceToDetector (0018,1110)";
const SOD: &str = "DistanceSourceToPatient (0018,1111)";
const MAG: &str = "EstimatedRadiographicMagnificationFactor (0018,1114)";
const SPACING: &str = "ImagerPixelSpacing (0018,1164) or PixelSpacing (0028,0030)";

/// What a view takes from an X-ray DICOM file.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct DicomGeometry {
    /// Rows (0028,0010): the image height, pixels.
    pub rows: u32,
    /// Columns (0028,0011): the image width, pixels.
    pub columns: u32,
    /// Modality (0008,0060), when given (DX, CR).
    pub modality: Option<String>,
    /// Pixel spacing (row, column), mm, and where it came from.
    pub spacing_mm: Option<[f64; 2]>,
    /// The tag the spacing came from.
    pub spacing_tag: Option<SpacingTag>,
    /// Source to detector, mm.
    pub sid_mm: Option<f64>,
    /// Source to patient, mm.
    pub sod_mm: Option<f64>,
}

impl DicomGeometry {
    /// Focal lengths (fx, fy) in pixels: SID / column spacing, SID / row spacing.
    pub fn focal_px(&self, path: &Path) -> Result<(f64, f64), DicomError> {
        let missing = |tag: &str| DicomError::Missing {
            path: path.to_path_buf(),
            tag: tag.into(),
            why: "the view gives no k.fx/k.fy, so the focal length is SID / pixel spacing".into(),
        };
        let s = self.spacing_mm.ok_or_else(|| missing(SPACING))?;
        let sid = self.sid_mm.ok_or_else(|| missing(SID))?;
        Ok((sid / s[1], sid / s[0]))
    }

    /// Magnification at the object, SID / SOD, when both are given.
    pub fn magnification(&self) -> Option<f64> {
        Some(self.sid_mm? / self.sod_mm?)
    }
}

/// Whether `path` is a DICOM Part 10 file ("DICM" after the 128-byte preamble).
pub fn is_dicom(path: &Path) -> bool {
    use std::io::Read;
    let mut head = [0u8; 132];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok()
        && &head[128..] == b"DICM"
}

fn open(path: &Path) -> Result<dicom_object::DefaultDicomObject, DicomError> {
    dicom_object::open_file(path).map_err(|e| DicomError::Read {
        path: path.to_path_buf(),
        reason: super::printable(&e.to_string()),
    })
}

/// Numbers of a decimal-string tag, None when absent or empty; an error when unreadable,
/// non-finite or not positive.
fn positive_values(
    obj: &InMemDicomObject,
    path: &Path,
    tag: Tag,
    label: &str,
) -> Result<Option<Vec<f64>>, DicomError> {
    let Some(e) = obj.element_opt(tag).ok().flatten() else {
        return Ok(None);
    };
    if e.is_empty() {
        return Ok(None);
    }
    let bad = |value: String, reason: &str| DicomError::Tag {
        path: path.to_path_buf(),
        tag: label.into(),
        value: super::shown(&value),
        reason: reason.into(),
    };
    let v = e.to_multi_float64().map_err(|err| {
        bad(
            format!("{:?}", e.to_str().unwrap_or_default()),
            &super::printable(&err.to_string()),
        )
    })?;
    if v.is_empty() {
        return Ok(None);
    }
    if v.iter().any(|x| !(x.is_finite() && *x > 0.0)) {
        return Err(bad(format!("{v:?}"), "must be positive"));
    }
    Ok(Some(v))
}

fn uint(obj: &InMemDicomObject, path: &Path, tag: Tag, label: &str) -> Result<u32, DicomError> {
    let e = obj
        .element_opt(tag)
        .ok()
        .flatten()
        .ok_or_else(|| DicomError::Missing {
            path: path.to_path_buf(),
            tag: label.into(),
            why: "an X-ray image needs it".into(),
        })?;
    e.to_int::<u32>().map_err(|err| DicomError::Tag {
        path: path.to_path_buf(),
        tag: label.into(),
        value: format!("{:?}", e.to_str().unwrap_or_default()),
        reason: super::printable(&err.to_string()),
    })
}

fn geometry_of(obj: &InMemDicomObject, path: &Path) -> Result<DicomGeometry, DicomError> {
    if obj.element_opt(tags::PIXEL_DATA).ok().flatten().is_none() {
        let sop = obj
            .element_opt(tags::SOP_CLASS_UID)
            .ok()
            .flatten()
            .and_then(|e| {
                e.to_str()
                    .ok()
                    .map(|s| s.trim_end_matches('\0').to_string())
            })
            .unwrap_or_else(|| "none".into());
        return Err(DicomError::Missing {
            path: path.to_path_buf(),
            tag: "PixelData (7FE0,0010)".into(),
            why: format!("this is not an image (SOP class {sop}); a view needs a DX or CR X-ray"),
        });
    }
    let rows = uint(obj, path, tags::ROWS, "Rows (0028,0010)")?;
    let columns = uint(obj, path, tags::COLUMNS, "Columns (0028,0011)")?;
    for (v, label) in [(rows, "Rows (0028,0010)"), (columns, "Columns (0028,0011)")] {
        if v == 0 || v > 65536 {
            return Err(DicomError::Tag {
                path: path.to_path_buf(),
                tag: label.into(),
                value: v.to_string(),
                reason: "must be 1..65536".into(),
            });
        }
    }
    let modality = obj
        .element_opt(tags::MODALITY)
        .ok()
        .flatten()
        .and_then(|e| e.to_str().ok().map(|s| s.trim().to_string()));
    let mut spacing = None;
    for which in [SpacingTag::Imager, SpacingTag::Pixel] {
        if let Some(v) = positive_values(obj, path, which.tag(), which.label())? {
            if v.len() != 2 {
                return Err(DicomError::Tag {
                    path: path.to_path_buf(),
                    tag: which.label().into(),
                    value: format!("{v:?}"),
                    reason: "must hold two values (row spacing \\ column spacing, mm)".into(),
                });
            }
            spacing = Some(([v[0], v[1]], which));
            break;
        }
    }
    let one = |tag, label| -> Result<Option<f64>, DicomError> {
        Ok(positive_values(obj, path, tag, label)?.map(|v| v[0]))
    };
    let sid_mm = one(tags::DISTANCE_SOURCE_TO_DETECTOR, SID)?;
    let sod_mm = one(tags::DISTANCE_SOURCE_TO_PATIENT, SOD)?;
    if let (Some(sid), Some(sod)) = (sid_mm, sod_mm) {
        if sod >= sid {
            return Err(DicomError::Tag {
                path: path.to_path_buf(),
                tag: SOD.into(),
                value: format!("{sod}"),
                reason: format!(
                    "the patient cannot be as far from the source as the detector ({SID} = {sid})"
                ),
            });
        }
        if let Some(m) = one(tags::ESTIMATED_RADIOGRAPHIC_MAGNIFICATION_FACTOR, MAG)? {
            let implied = sid / sod;
            if (m / implied - 1.0).abs() > 0.01 {
                return Err(DicomError::Tag {
                    path: path.to_path_buf(),
                    tag: MAG.into(),
                    value: format!("{m}"),
                    reason: format!(
                        "contradicts SID / SOD = {sid} / {sod} = {implied:.4} by more than 1 %"
                    ),
                });
            }
        }
    }
    Ok(DicomGeometry {
        rows,
        columns,
        modality,
        spacing_mm: spacing.map(|s| s.0),
        spacing_tag: spacing.map(|s| s.1),
        sid_mm,
        sod_mm,
    })
}

/// The geometry of the X-ray in the DICOM file at `path` (refused: a file that is not DICOM, one
/// without pixel data, sizes or distances that cannot be right).
pub fn read_dicom_geometry(path: &Path) -> Result<DicomGeometry, DicomError> {
    let obj = open(path)?;
    geometry_of(&obj, path)
}

/// The X-ray's pixels as 8-bit grey, windowed as the file says (or stretched over its range when
/// it says nothing), bright bone as on a film (MONOCHROME1 is inverted).
pub fn read_dicom_image(path: &Path) -> Result<image::GrayImage, DicomError> {
    let obj = open(path)?;
    let geo = geometry_of(&obj, path)?;
    let tag_err = |tag: &str, value: String, reason: String| DicomError::Tag {
        path: path.to_path_buf(),
        tag: tag.into(),
        value,
        reason,
    };
    let bad = |reason: String| {
        tag_err(
            "PixelData (7FE0,0010)",
            format!("{}x{}", geo.columns, geo.rows),
            reason,
        )
    };
    let decoded = obj
        .decode_pixel_data_frame(0)
        .map_err(|e| bad(format!("cannot be decoded: {e}")))?;
    if decoded.samples_per_pixel() != 1 {
        return Err(bad(format!(
            "{} samples per pixel; an X-ray is grey (1)",
            decoded.samples_per_pixel()
        )));
    }
    // The conversion below reads 1, 8 or 16 bits a pixel, builds a table of 2^BitsStored entries
    // and asserts on a BitsStored of 0 or over 32: a value the pixels cannot have is refused
    // here, with the tag named.
    let (stored, allocated) = (decoded.bits_stored(), decoded.bits_allocated());
    if !matches!(allocated, 1 | 8 | 16) {
        return Err(tag_err(
            "BitsAllocated (0028,0100)",
            allocated.to_string(),
            "must be 1, 8 or 16 for a grey X-ray".into(),
        ));
    }
    if stored == 0 || stored > allocated {
        return Err(tag_err(
            "BitsStored (0028,0101)",
            stored.to_string(),
            format!("must be 1 to BitsAllocated (0028,0100) = {allocated}"),
        ));
    }
    // Modality values, then the file's first window (linear), or its range when it has none.
    let raw: Vec<f32> = decoded
        .to_vec_frame(0)
        .map_err(|e| bad(format!("cannot be converted: {e}")))?;
    let first = |tag| {
        obj.element_opt(tag)
            .ok()
            .flatten()
            .and_then(|e| e.to_multi_float64().ok())
            .and_then(|v| v.first().copied())
    };
    let (lo, hi) = match (first(tags::WINDOW_CENTER), first(tags::WINDOW_WIDTH)) {
        (Some(c), Some(w)) if c.is_finite() && w.is_finite() && w >= 1.0 => {
            ((c - 0.5 * w) as f32, (c + 0.5 * w) as f32)
        }
        _ => raw
            .iter()
            .filter(|v| v.is_finite())
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            }),
    };
    let span = (hi - lo).max(1e-6);
    let mut px: Vec<u8> = raw
        .iter()
        .map(|v| (255.0 * ((v - lo) / span)).clamp(0.0, 255.0) as u8)
        .collect();
    let inverted = obj
        .element_opt(tags::PHOTOMETRIC_INTERPRETATION)
        .ok()
        .flatten()
        .and_then(|e| e.to_str().ok().map(|s| s.trim() == "MONOCHROME1"))
        .unwrap_or(false);
    if inverted {
        px.iter_mut().for_each(|v| *v = 255 - *v);
    }
    image::GrayImage::from_raw(geo.columns, geo.rows, px)
        .ok_or_else(|| bad("holds fewer pixels than Rows x Columns".into()))
}

/// An X-ray written by `write_dicom_xray`: 16-bit grey pixels (12 bits used) and the tags a view's
/// geometry follows from; a tag left `None` is not written.
#[derive(Clone, Debug)]
pub struct DicomXray {
    /// Image width, pixels.
    pub columns: u32,
    /// Image height, pixels.
    pub rows: u32,
    /// Row-major pixels, 0..4095 (brighter is denser).
    pub pixels: Vec<u16>,
    /// Pixel spacing (row, column), mm, and the tag it is written to.
    pub spacing: Option<([f64; 2], SpacingTag)>,
    /// Source to detector, mm.
    pub sid_mm: Option<f64>,
    /// Source to patient, mm.
    pub sod_mm: Option<f64>,
    /// The view's name (Series Description and View Position).
    pub view: String,
    /// A number that makes the file's UIDs its own (the same number gives the same file).
    pub uid_seed: u64,
}

fn ds(v: f64) -> String {
    // A decimal string holds at most 16 characters.
    let s = format!("{v}");
    if s.len() <= 16 {
        s
    } else {
        format!("{v:.10e}")
    }
}

/// Write `x` as a Digital X-Ray (for presentation) file, Deflated Explicit VR Little Endian.
pub fn write_dicom_xray(path: &Path, x: &DicomXray) -> Result<(), DicomError> {
    let werr = |reason: String| DicomError::Write {
        path: path.to_path_buf(),
        reason,
    };
    if x.pixels.len() != x.rows as usize * x.columns as usize {
        return Err(werr(format!(
            "{} pixels for a {}x{} image",
            x.pixels.len(),
            x.columns,
            x.rows
        )));
    }
    let uid = |kind: u64| format!("2.25.{}", (u128::from(x.uid_seed) << 16) + u128::from(kind));
    let sop_instance = uid(3);
    let mut obj = InMemDicomObject::new_empty();
    let text = |obj: &mut InMemDicomObject, tag, vr, s: &str| {
        obj.put(DataElement::new(tag, vr, PrimitiveValue::from(s)));
    };
    text(
        &mut obj,
        tags::SOP_CLASS_UID,
        VR::UI,
        uids::DIGITAL_X_RAY_IMAGE_STORAGE_FOR_PRESENTATION,
    );
    text(&mut obj, tags::SOP_INSTANCE_UID, VR::UI, &sop_instance);
    text(&mut obj, tags::STUDY_INSTANCE_UID, VR::UI, &uid(1));
    text(&mut obj, tags::SERIES_INSTANCE_UID, VR::UI, &uid(2));
    text(&mut obj, tags::MODALITY, VR::CS, "DX");
    text(&mut obj, tags::PATIENT_NAME, VR::PN, "Phantom^Acetab");
    text(&mut obj, tags::PATIENT_ID, VR::LO, "ACETAB-PHANTOM");
    text(&mut obj, tags::SERIES_DESCRIPTION, VR::LO, &x.view);
    text(
        &mut obj,
        tags::PRESENTATION_INTENT_TYPE,
        VR::CS,
        "FOR PRESENTATION",
    );
    text(
        &mut obj,
        tags::PHOTOMETRIC_INTERPRETATION,
        VR::CS,
        "MONOCHROME2",
    );
    let us = |obj: &mut InMemDicomObject, tag, v: u16| {
        obj.put(DataElement::new(tag, VR::US, PrimitiveValue::from(v)));
    };
    let dim = |v: u32| u16::try_from(v).map_err(|_| werr(format!("size {v} over 65535")));
    us(&mut obj, tags::ROWS, dim(x.rows)?);
    us(&mut obj, tags::COLUMNS, dim(x.columns)?);
    us(&mut obj, tags::SAMPLES_PER_PIXEL, 1);
    us(&mut obj, tags::BITS_ALLOCATED, 16);
    us(&mut obj, tags::BITS_STORED, 12);
    us(&mut obj, tags::HIGH_BIT, 11);
    us(&mut obj, tags::PIXEL_REPRESENTATION, 0);
    text(&mut obj, tags::WINDOW_CENTER, VR::DS, "2048");
    text(&mut obj, tags::WINDOW_WIDTH, VR::DS, "4096");
    if let Some((s, which)) = x.spacing {
        obj.put(DataElement::new(
            which.tag(),
            VR::DS,
            PrimitiveValue::Strs([ds(s[0]), ds(s[1])].into_iter().collect()),
        ));
    }
    if let Some(v) = x.sid_mm {
        text(&mut obj, tags::DISTANCE_SOURCE_TO_DETECTOR, VR::DS, &ds(v));
    }
    if let Some(v) = x.sod_mm {
        text(&mut obj, tags::DISTANCE_SOURCE_TO_PATIENT, VR::DS, &ds(v));
    }
    if let (Some(sid), Some(sod)) = (x.sid_mm, x.sod_mm) {
        text(
            &mut obj,
            tags::ESTIMATED_RADIOGRAPHIC_MAGNIFICATION_FACTOR,
            VR::DS,
            &ds(sid / sod),
        );
    }
    let pixels: C<u16> = x.pixels.iter().map(|v| (*v).min(4095)).collect();
    obj.put(DataElement::new(
        tags::PIXEL_DATA,
        VR::OW,
        PrimitiveValue::U16(pixels),
    ));
    let file = obj
        .with_meta(
            FileMetaTableBuilder::new()
                .transfer_syntax(uids::DEFLATED_EXPLICIT_VR_LITTLE_ENDIAN)
                .media_storage_sop_class_uid(uids::DIGITAL_X_RAY_IMAGE_STORAGE_FOR_PRESENTATION)
                .media_storage_sop_instance_uid(sop_instance.as_str()),
        )
        .map_err(|e| werr(super::printable(&e.to_string())))?;
    let mut bytes = Vec::new();
    file.write_all(&mut bytes)
        .map_err(|e| werr(super::printable(&e.to_string())))?;
    crate::io::write_atomic(path, &bytes).map_err(|e| werr(super::printable(&e.to_string())))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::printable;

    fn xray(spacing: Option<([f64; 2], SpacingTag)>, sid: Option<f64>) -> DicomXray {
        DicomXray {
            columns: 40,
            rows: 30,
            pixels: (0..1200).map(|i| (i * 3 % 4096) as u16).collect(),
            spacing,
            sid_mm: sid,
            sod_mm: Some(900.0),
            view: "AP".into(),
            uid_seed: 7,
        }
    }

    #[test]
    fn geometry_and_pixels_survive_a_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.dcm");
        write_dicom_xray(
            &p,
            &xray(Some(([0.2, 0.25], SpacingTag::Imager)), Some(1100.0)),
        )
        .unwrap();
        assert!(is_dicom(&p));
        let g = read_dicom_geometry(&p).unwrap();
        assert_eq!((g.columns, g.rows), (40, 30));
        assert_eq!(g.spacing_tag, Some(SpacingTag::Imager));
        let (fx, fy) = g.focal_px(&p).unwrap();
        assert!(
            (fx - 4400.0).abs() < 1e-9 && (fy - 5500.0).abs() < 1e-9,
            "{fx} {fy}"
        );
        assert!((g.magnification().unwrap() - 1100.0 / 900.0).abs() < 1e-12);
        let img = read_dicom_image(&p).unwrap();
        assert_eq!(img.dimensions(), (40, 30));
        // Window 2048 / 4096 maps 0..4095 onto 0..255: a pixel's grey follows its value.
        let (lo, hi) = (img.get_pixel(0, 0).0[0], img.get_pixel(39, 29).0[0]);
        assert!(lo < 5 && hi > 200, "{lo} {hi}");
    }

    #[test]
    fn a_missing_spacing_or_distance_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.dcm");
        write_dicom_xray(&p, &xray(None, Some(1100.0))).unwrap();
        let e = read_dicom_geometry(&p).unwrap().focal_px(&p).unwrap_err();
        assert!(e.to_string().contains("(0018,1164)"), "{e}");
        write_dicom_xray(&p, &xray(Some(([0.2, 0.2], SpacingTag::Pixel)), None)).unwrap();
        let g = read_dicom_geometry(&p).unwrap();
        assert_eq!(g.spacing_tag, Some(SpacingTag::Pixel));
        let e = g.focal_px(&p).unwrap_err();
        assert!(e.to_string().contains("(0018,1110)"), "{e}");
    }

    #[test]
    fn a_patient_beyond_the_detector_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.dcm");
        let mut x = xray(Some(([0.2, 0.2], SpacingTag::Imager)), Some(800.0));
        x.sod_mm = Some(900.0);
        // The writer adds a magnification of SID / SOD; it is the SOD that is wrong.
        write_dicom_xray(&p, &x).unwrap();
        let e = read_dicom_geometry(&p).unwrap_err().to_string();
        assert!(e.contains("(0018,1111)") && e.contains("c.dcm"), "{e}");
    }

    /// A sound X-ray written to `p`, then its US tag `tag` set to `v`.
    fn xray_with_us(p: &Path, tag: Tag, v: u16) {
        write_dicom_xray(
            p,
            &xray(Some(([0.2, 0.2], SpacingTag::Imager)), Some(1100.0)),
        )
        .unwrap();
        let mut obj = dicom_object::open_file(p).unwrap();
        obj.put(DataElement::new(tag, VR::US, PrimitiveValue::from(v)));
        obj.write_to_file(p).unwrap();
    }

    #[test]
    fn bits_stored_the_pixels_cannot_have_is_named_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("d.dcm");
        for bits in [0, 17, 32, 40] {
            xray_with_us(&p, tags::BITS_STORED, bits);
            let e = read_dicom_image(&p).unwrap_err().to_string();
            assert!(
                e.contains("d.dcm") && e.contains("(0028,0101)") && e.contains(&bits.to_string()),
                "{e}"
            );
            // For drawing, the caller names the file: the reason comes without it.
            let r = crate::io::read_xray_image(&p).unwrap_err();
            assert!(
                r.starts_with("DICOM tag BitsStored (0028,0101)") && !r.contains("d.dcm"),
                "{r}"
            );
        }
    }

    #[test]
    fn bits_allocated_the_conversion_cannot_read_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.dcm");
        for bits in [0u16, 7] {
            xray_with_us(&p, tags::BITS_ALLOCATED, bits);
            let e = read_dicom_image(&p).unwrap_err().to_string();
            assert!(
                e.contains("f.dcm")
                    && e.contains("BitsAllocated (0028,0100) = ")
                    && e.contains(&format!("= {bits}:")),
                "{e}"
            );
        }
    }

    #[test]
    fn bits_stored_up_to_bits_allocated_reads() {
        // The companion: the check refuses no value the pixels can have.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("e.dcm");
        for bits in [1, 12, 16] {
            xray_with_us(&p, tags::BITS_STORED, bits);
            let img = read_dicom_image(&p).unwrap();
            assert_eq!(img.dimensions(), (40, 30), "bits stored {bits}");
            assert!(crate::io::read_xray_image(&p).is_ok(), "bits stored {bits}");
        }
    }

    #[test]
    fn a_png_is_not_dicom() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.png");
        image::GrayImage::new(4, 4).save(&p).unwrap();
        assert!(!is_dicom(&p));
        let e = read_dicom_geometry(&p).unwrap_err().to_string();
        assert!(
            e.contains("x.png") && e.contains("not a readable DICOM"),
            "{e}"
        );
    }

    /// A file whose transfer syntax UID was overwritten with NULs: the reader's message quotes
    /// the UID, and it comes out with the NULs escaped (before, raw NULs went to the terminal
    /// and into cases.csv). Companion: the shipped example's file as it is reads.
    #[test]
    fn a_corrupt_files_bytes_are_quoted_printable() {
        let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/case-dicom/view0.dcm");
        let mut bytes = std::fs::read(&shipped).unwrap();
        let uid = b"1.2.840.10008.1.2";
        let at = bytes.windows(uid.len()).position(|w| w == uid).unwrap();
        bytes[at..at + 7].fill(0);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("nul.dcm");
        std::fs::write(&p, &bytes).unwrap();
        let e = read_dicom_geometry(&p).unwrap_err().to_string();
        assert!(e.contains("nul.dcm") && e.contains("`\\u{0}\\u{0}"), "{e}");
        assert!(!e.chars().any(|c| c.is_control()), "{e:?}");
        assert!(read_dicom_geometry(&shipped).is_ok());
        assert_eq!(printable("a\0b\u{1b}[2J\tc\nd"), "a\\u{0}b\\u{1b}[2J\tc\nd");
    }
}
