//! Values as error messages give them: a number too long to read (a value of 1e300 written out
//! is 301 digits) in scientific notation, everything else as it was written; and a message that
//! quotes a file's bytes (a DICOM reader's) with its control characters escaped.

/// Most digits before the point a number is shown with as written ...
const INTEGER_DIGITS: usize = 12;
/// ... and most zeros after "0."; beyond either it is shown as `{:e}` (1.5e300, 2e-300).
const LEADING_ZEROS: usize = 8;

/// Whether a number written as `token` is too long to read.
fn too_long(token: &str) -> bool {
    let digits = token.trim_start_matches(['-', '+']);
    let (int, frac) = digits.split_once('.').unwrap_or((digits, ""));
    int.len() > INTEGER_DIGITS
        || (int.trim_start_matches('0').is_empty()
            && frac.len() - frac.trim_start_matches('0').len() > LEADING_ZEROS)
}

/// `text` with every control character but a newline or a tab escaped (`\u{0}`, `\u{1b}`), so
/// that a message quoting a corrupt file's bytes neither writes NULs into a CSV's error column
/// nor moves the terminal's cursor.
pub fn printable(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_control() && c != '\n' && c != '\t' {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// `text` (a value as `Display` or `Debug` writes it: a number, a list of numbers, a word) with
/// every number too long to read (more than `INTEGER_DIGITS` digits before the point, or more
/// than `LEADING_ZEROS` zeros after "0.") in scientific notation.
pub fn shown(text: &str) -> String {
    let is_num = |c: char| c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E');
    let mut out = String::with_capacity(text.len().min(64));
    let mut rest = text;
    while let Some(start) = rest.find(|c: char| c.is_ascii_digit()) {
        // A number starts at its sign or its first digit.
        let start = if rest[..start].ends_with('-') {
            start - 1
        } else {
            start
        };
        out.push_str(&rest[..start]);
        let len = rest[start..]
            .find(|c: char| !is_num(c))
            .unwrap_or(rest.len() - start);
        let token = &rest[start..start + len];
        match token.parse::<f64>() {
            Ok(v) if !token.contains(['e', 'E']) && too_long(token) => {
                out.push_str(&format!("{v:e}"))
            }
            _ => out.push_str(token),
        }
        rest = &rest[start + len..];
    }
    out.push_str(rest);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 301-digit value and a list of 17- and 18-character coordinates are shortened; companions:
    /// ordinary numbers, words with digits in them and non-finite values stay as written.
    #[test]
    fn only_numbers_too_long_to_read_are_shortened() {
        assert_eq!(shown(&1e300.to_string()), "1e300");
        assert_eq!(shown(&(-1.5e300).to_string()), "-1.5e300");
        assert_eq!(shown(&2e-300.to_string()), "2e-300");
        assert_eq!(
            shown("[1133058499141736.8, 905563512699820.3]"),
            "[1.1330584991417368e15, 9.055635126998203e14]"
        );
        for plain in [
            "1000000",
            "-1",
            "0.000123",
            "3.6078532024372847",
            "NaN",
            "inf",
            "view1.png",
        ] {
            assert_eq!(shown(plain), plain);
        }
        assert_ne!(shown(&1e300.to_string()), 1e300.to_string());
    }
}
