//! JSON read into the program's types, with the field that failed named: serde_json's message
//! says where in the text, `serde_path_to_error` says which field (views[0].k.fx).

use serde::de::DeserializeOwned;

/// Parse `text` as a `T`. The error reads "field PATH: serde's message (line, column)", or
/// serde's message alone when it failed before any field (empty text, a bad first token).
pub fn parse_json<T: DeserializeOwned>(text: &str) -> Result<T, String> {
    let mut de = serde_json::Deserializer::from_str(text);
    let value = serde_path_to_error::deserialize(&mut de).map_err(|e| shown_error(&e))?;
    // Trailing characters after the value are an error too, as in serde_json::from_str.
    de.end().map_err(|e| e.to_string())?;
    Ok(value)
}

fn shown_error(e: &serde_path_to_error::Error<serde_json::Error>) -> String {
    let field = e.path().to_string();
    if field.is_empty() || field == "." {
        e.inner().to_string()
    } else {
        format!("field {field}: {}", e.inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct K {
        #[allow(dead_code)]
        fx: f64,
    }
    #[derive(Debug, serde::Deserialize)]
    struct View {
        #[allow(dead_code)]
        k: K,
    }
    #[derive(Debug, serde::Deserialize)]
    struct Case {
        views: Vec<View>,
    }

    #[test]
    fn a_wrong_type_names_the_field_and_the_value() {
        let e =
            parse_json::<Case>(r#"{"views": [{"k": {"fx": 1}}, {"k": {"fx": "x"}}]}"#).unwrap_err();
        assert!(e.starts_with("field views[1].k.fx: "), "{e}");
        assert!(e.contains("string \"x\""), "{e}");
        assert!(e.contains("line 1"), "{e}");
    }

    #[test]
    fn a_good_text_parses_and_trailing_text_is_refused() {
        let c = parse_json::<Case>(r#"{"views": [{"k": {"fx": 1}}]}"#).unwrap();
        assert_eq!(c.views.len(), 1);
        let e = parse_json::<Case>(r#"{"views": []} x"#).unwrap_err();
        assert!(e.contains("trailing characters"), "{e}");
    }

    #[test]
    fn an_error_before_any_field_is_serdes_message_alone() {
        let e = parse_json::<Case>("").unwrap_err();
        assert!(!e.starts_with("field"), "{e}");
        assert!(e.contains("EOF"), "{e}");
    }
}
