//! Acetabular cup catalogue: the sizes a surgeon can implant, and the nearest one to a diameter.

/// Outer diameters on offer, mm (default 40 to 70 in 2 mm steps).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CupCatalogue {
    /// Cup outer diameters on offer, mm, ascending.
    pub sizes_mm: Vec<f64>,
}

impl Default for CupCatalogue {
    fn default() -> Self {
        CupCatalogue {
            sizes_mm: (0..=15).map(|k| 40.0 + 2.0 * k as f64).collect(),
        }
    }
}

/// A chosen size.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct CupSize {
    /// The fitted diameter, mm.
    pub diameter_mm: f64,
    /// The nearest size in the catalogue, mm.
    pub catalogue_mm: f64,
}

impl CupCatalogue {
    /// From "min:max:step" or a comma-separated list of sizes.
    pub fn parse(s: &str) -> Result<CupCatalogue, String> {
        let sizes: Vec<f64> = if s.contains(':') {
            let p: Vec<&str> = s.split(':').collect();
            let nums: Result<Vec<f64>, _> = p.iter().map(|x| x.trim().parse::<f64>()).collect();
            match nums.as_deref() {
                Ok([a, b, st]) if *st > 0.0 && b >= a && (b - a) / st < 1e4 => {
                    let n = ((b - a) / st + 1e-9).floor() as usize;
                    (0..=n).map(|k| a + st * k as f64).collect()
                }
                _ => {
                    return Err(format!(
                        "catalogue {s:?}: expected min:max:step with step > 0, max >= min and at most 10,000 sizes"
                    ))
                }
            }
        } else {
            s.split(',')
                .map(|x| {
                    x.trim()
                        .parse::<f64>()
                        .map_err(|_| format!("catalogue size {x:?} is not a number"))
                })
                .collect::<Result<_, _>>()?
        };
        if sizes.is_empty() || sizes.iter().any(|v| !v.is_finite() || *v <= 0.0) {
            return Err(format!(
                "catalogue {s:?}: sizes must be positive finite numbers"
            ));
        }
        let mut sizes = sizes;
        sizes.sort_by(f64::total_cmp);
        if let Some(w) = sizes.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("catalogue {s:?}: size {} is listed twice", w[0]));
        }
        Ok(CupCatalogue { sizes_mm: sizes })
    }

    /// Whether the sizes are a catalogue: at least one, each finite and > 0, ascending without
    /// repeats (what `parse` makes; the field is public, and a host may fill it itself).
    pub fn is_well_formed(&self) -> bool {
        !self.sizes_mm.is_empty()
            && self.sizes_mm.iter().all(|v| v.is_finite() && *v > 0.0)
            && self.sizes_mm.windows(2).all(|w| w[0] < w[1])
    }

    /// Whether the catalogue can hold a cup of `diameter`: it lies no further below the smallest
    /// size, or above the largest, than half the step to its neighbour (1 mm for a catalogue
    /// of one size). A cup outside is not sized: the nearest size would be a guess.
    pub fn holds(&self, diameter: f64) -> bool {
        let (Some(&lo), Some(&hi)) = (self.sizes_mm.first(), self.sizes_mm.last()) else {
            return false;
        };
        let n = self.sizes_mm.len();
        let below = if n > 1 { self.sizes_mm[1] - lo } else { 2.0 };
        let above = if n > 1 {
            hi - self.sizes_mm[n - 2]
        } else {
            2.0
        };
        diameter.is_finite() && diameter >= lo - 0.5 * below && diameter <= hi + 0.5 * above
    }

    /// The nearest catalogue size (ties go to the larger cup). An empty catalogue (one built
    /// by hand; `parse` refuses it) has no size to offer: NaN.
    pub fn nearest(&self, diameter: f64) -> CupSize {
        let best = self.sizes_mm.iter().fold(f64::NAN, |best, &s| {
            if best.is_nan() || (s - diameter).abs() <= (best - diameter).abs() {
                s
            } else {
                best
            }
        });
        CupSize {
            diameter_mm: diameter,
            catalogue_mm: best,
        }
    }

    /// How many catalogue steps lie between the nearest sizes of two diameters (0: the same
    /// size; 1: neighbouring sizes); None for an empty catalogue or a diameter that is not a
    /// number.
    pub fn sizes_apart(&self, a: f64, b: f64) -> Option<usize> {
        let index = |d: f64| {
            let size = self.nearest(d).catalogue_mm;
            self.sizes_mm.iter().position(|&s| s == size)
        };
        match (a.is_finite() && b.is_finite(), index(a), index(b)) {
            (true, Some(i), Some(j)) => Some(i.abs_diff(j)),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_cup_outside_the_catalogue_is_not_held() {
        let c = CupCatalogue::parse("60:70:2").unwrap();
        assert!(c.holds(59.0) && c.holds(71.0) && c.holds(65.3));
        assert!(!c.holds(51.0) && !c.holds(58.9) && !c.holds(71.1) && !c.holds(f64::NAN));
        let one = CupCatalogue::parse("52").unwrap();
        assert!(one.holds(51.5) && !one.holds(49.0));
    }

    #[test]
    fn sizes_apart_counts_catalogue_steps() {
        let c = CupCatalogue::default();
        // 52.9 is nearest 52, 53.0 nearest 54 (ties go up): one size apart; 50.9 (50) is two
        // from 53.0.
        assert_eq!(c.sizes_apart(52.9, 53.0), Some(1));
        assert_eq!(c.sizes_apart(53.0, 53.9), Some(0));
        assert_eq!(c.sizes_apart(50.9, 53.0), Some(2));
        assert_eq!(c.sizes_apart(53.0, 50.9), Some(2));
        // Companion: a diameter that is not a number is no size at all.
        assert_eq!(c.sizes_apart(f64::NAN, 53.0), None);
        assert_eq!(
            CupCatalogue { sizes_mm: vec![] }.sizes_apart(50.0, 50.0),
            None
        );
    }

    #[test]
    fn nearest_size_and_parsing() {
        let c = CupCatalogue::default();
        assert_eq!(c.sizes_mm.len(), 16);
        assert_eq!(c.nearest(52.9).catalogue_mm, 52.0);
        assert_eq!(c.nearest(53.0).catalogue_mm, 54.0);
        assert_eq!(c.nearest(10.0).catalogue_mm, 40.0);
        assert_eq!(
            CupCatalogue::parse("44:50:3").unwrap().sizes_mm,
            vec![44.0, 47.0, 50.0]
        );
        assert_eq!(
            CupCatalogue::parse("52, 48").unwrap().sizes_mm,
            vec![48.0, 52.0]
        );
        assert!(CupCatalogue::parse("40:30:2").is_err());
        assert!(CupCatalogue::parse("a,b").is_err());
        assert!(CupCatalogue::parse("-4").is_err());
        let e = CupCatalogue::parse("48, 50, 48").unwrap_err();
        assert!(e.contains("size 48 is listed twice"), "{e}");
        let e = CupCatalogue::parse("1e9:1e10:1").unwrap_err();
        assert!(e.contains("at most 10,000 sizes"), "{e}");
    }

    #[test]
    fn an_empty_catalogue_offers_no_size_instead_of_panicking() {
        let empty = CupCatalogue { sizes_mm: vec![] };
        let c = empty.nearest(52.0);
        assert!(c.catalogue_mm.is_nan() && c.diameter_mm == 52.0);
        // Companion: a one-size catalogue offers that size, however far.
        let one = CupCatalogue {
            sizes_mm: vec![60.0],
        };
        assert_eq!(one.nearest(40.0).catalogue_mm, 60.0);
    }
}
