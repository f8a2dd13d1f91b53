//! Test fixtures shared by the integration tests and the bench: ONNX models with random weights
//! written by `make_fixtures.py` (PyTorch + `onnx`), plus torch's outputs for random inputs.
//!
//! Python is `$FORMATION_PYTHON`, else the repository's `.venv/bin/python`. Without a Python that
//! has torch and onnx the tests fail with the fix.

#![allow(dead_code)] // each test binary uses a different part

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// Image side of the fixture models.
pub const SIZE_PX: usize = 50;

/// Where the fixture files are.
pub struct Fixtures {
    /// Directory holding `policy.onnx` and friends.
    pub dir: PathBuf,
}

impl Fixtures {
    /// Path of one fixture file.
    pub fn model(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// The torch reference cases: (occupancy, aux, torch's wheels).
    pub fn cases(&self) -> Vec<(Vec<f32>, [f32; 2], [f32; 2])> {
        let bytes = std::fs::read(self.dir.join("cases.f32"))
            .expect("cases.f32 written by make_fixtures.py");
        let values: Vec<f32> = bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        let cells = SIZE_PX * SIZE_PX;
        values
            .chunks_exact(cells + 4)
            .map(|r| {
                (
                    r[..cells].to_vec(),
                    [r[cells], r[cells + 1]],
                    [r[cells + 2], r[cells + 3]],
                )
            })
            .collect()
    }
}

/// Number of torch reference cases written.
pub const CASES: usize = 16;

/// The fixtures of this test binary (regenerated once per process in
/// `target/tmp/formation-onnx-<tag>`); without Python, torch and onnx the test fails with the fix.
pub fn fixtures(tag: &str) -> &'static Fixtures {
    static FIXTURES: OnceLock<Result<Fixtures, String>> = OnceLock::new();
    match FIXTURES.get_or_init(|| generate(tag)) {
        Ok(fixtures) => fixtures,
        Err(why) => panic!(
            "{why}\nthese tests need Python with torch and onnx: run `bash .ci/setup-python --train`, or set \
             FORMATION_PYTHON=/path/to/python"
        ),
    }
}

fn python() -> PathBuf {
    match std::env::var_os("FORMATION_PYTHON") {
        Some(p) if !p.is_empty() => PathBuf::from(p),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("../.venv/bin/python"),
    }
}

fn generate(tag: &str) -> Result<Fixtures, String> {
    let python = python();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("formation-onnx-{tag}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/common/make_fixtures.py");
    let output = Command::new(&python)
        .arg(&script)
        .arg(&dir)
        .arg(CASES.to_string())
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    if !output.status.success() {
        return Err(format!(
            "{} {} failed ({}):\n{}",
            python.display(),
            script.display(),
            output.status,
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    Ok(Fixtures { dir })
}
