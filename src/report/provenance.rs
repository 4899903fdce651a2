//! Where a result came from: the program's version, the command line, where the kernels ran and
//! with how many threads, and the seed. Written into report.json and summary.json, so a result
//! found later says how to make it again.

use serde::Serialize;

/// A result's provenance.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Provenance {
    /// `acetab`'s version (Cargo's).
    pub version: String,
    /// The command line, one entry an argument (empty when embedded without one).
    pub command_line: Vec<String>,
    /// "cpu" or "gpu".
    pub backend: String,
    /// The GPU adapter (name, type and API), when the kernels ran on one.
    pub adapter: Option<String>,
    /// Worker threads.
    pub threads: usize,
    /// The seed of the result's draws.
    pub seed: u64,
}

impl Provenance {
    /// This process's provenance: the version and command line filled in.
    pub fn here(backend: &str, adapter: Option<String>, threads: usize, seed: u64) -> Provenance {
        Provenance {
            version: env!("CARGO_PKG_VERSION").to_string(),
            command_line: std::env::args().collect(),
            backend: backend.to_string(),
            adapter,
            threads,
            seed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn provenance_names_the_version_and_the_command_line() {
        let p = Provenance::here("gpu", Some("llvmpipe".into()), 4, 9);
        assert_eq!(p.version, env!("CARGO_PKG_VERSION"));
        assert_eq!(p.command_line, std::env::args().collect::<Vec<_>>());
        let v = serde_json::to_value(&p).unwrap();
        assert_eq!(v["adapter"], "llvmpipe");
        assert_eq!(v["seed"], 9);
        // Companion: another backend's provenance differs.
        assert_ne!(p, Provenance::here("cpu", None, 4, 9));
    }
}
