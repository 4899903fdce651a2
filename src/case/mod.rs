//! Case files: a patient's views and annotated rims read from JSON (`file`), checked against one
//! another (`views_agree`, on `views::span_miss` and `views::centre_miss`), and the whole run of
//! one case, from the file to the written report (`run`).

mod calibration;
mod file;
mod run;
mod views_agree;

pub use calibration::{Calibrated, CalibrationChoice, CalibrationUsed};
pub use file::{
    open_arc, Case, CaseError, CaseFile, ContourFile, ContourKind, IntrinsicsFile, OpenArc,
    TemplateFile, ViewFile, ViewGeometry, MIN_HULL_FILL, OPEN_ARC_RATIO, OPEN_ARC_SHARE,
};
pub use run::{
    run_case, run_case_calibrated, run_case_with, solve_case, CaseRunError, CaseRunReport,
};
// The views' agreement checks, where they were before they moved to `views` (a host's input
// is held to them too).
pub use crate::views::MAX_OUTLINE_SPAN_RATIO;
pub use crate::views::{centre_miss, centre_spread, CentreMiss, MAX_CENTRE_MISS};
