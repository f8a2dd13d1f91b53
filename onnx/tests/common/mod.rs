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
        let values = self.f32_file("cases.f32");
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

impl Fixtures {
    /// A file of little-endian f32 values written by `make_fixtures.py`.
    fn f32_file(&self, name: &str) -> Vec<f32> {
        let bytes = std::fs::read(self.dir.join(name))
            .unwrap_or_else(|e| panic!("{name} written by make_fixtures.py: {e}"));
        bytes
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    }

    /// The torch reference cases of `ranges.onnx`: (occupancy, aux, ranges, torch's wheels).
    pub fn ranges_cases(&self) -> Vec<RangesCase> {
        self.cases_with_tensor("ranges_cases.f32", SECTORS)
    }

    /// The torch reference cases of `neighbours.onnx`: (occupancy, aux, neighbours, torch's
    /// wheels).
    pub fn neighbours_cases(&self) -> Vec<NeighboursCase> {
        self.cases_with_tensor("neighbours_cases.f32", SLOTS * 4)
    }

    /// The torch reference cases of a model with a tensor input of `width` values beside the
    /// image and the aux scalars, each written as (occupancy, aux, that tensor, torch's wheels).
    fn cases_with_tensor(&self, name: &str, width: usize) -> Vec<TensorCase> {
        let values = self.f32_file(name);
        let cells = SIZE_PX * SIZE_PX;
        values
            .chunks_exact(cells + 2 + width + 2)
            .map(|r| {
                let tensor = cells + 2;
                let wheels = tensor + width;
                (
                    r[..cells].to_vec(),
                    [r[cells], r[cells + 1]],
                    r[tensor..wheels].to_vec(),
                    [r[wheels], r[wheels + 1]],
                )
            })
            .collect()
    }
}

/// One torch reference case of `neighbours.onnx`: occupancy, aux, neighbours (4 values a slot)
/// and torch's wheels.
pub type NeighboursCase = TensorCase;

/// Slots of `neighbours.onnx`'s neighbour input.
pub const SLOTS: usize = 8;

/// One torch reference case of `ranges.onnx`: occupancy, aux, ranges and torch's wheels.
pub type RangesCase = TensorCase;

/// One torch reference case of a model with a tensor input beside the image: occupancy, aux, that
/// tensor and torch's wheels.
pub type TensorCase = (Vec<f32>, [f32; 2], Vec<f32>, [f32; 2]);

/// Sectors of `ranges.onnx`'s range input.
pub const SECTORS: usize = 100;

/// Number of torch reference cases written.
pub const CASES: usize = 16;

/// The fixtures of this test binary, in `target/tmp/formation-onnx-<tag>-<key>` where the key is
/// taken from `make_fixtures.py`'s bytes: written once and shared by every test process (nextest
/// runs one per test), and written anew when the script changes. Without Python, torch and onnx
/// the test fails with the fix.
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
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/common/make_fixtures.py");
    let source =
        std::fs::read(&script).map_err(|e| format!("cannot read {}: {e}", script.display()))?;
    let key = {
        use std::hash::{Hash, Hasher};
        let mut hasher = std::hash::DefaultHasher::new();
        (source, CASES).hash(&mut hasher);
        hasher.finish()
    };
    let dir =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("formation-onnx-{tag}-{key:016x}"));
    if dir.is_dir() {
        return Ok(Fixtures { dir });
    }
    // Written beside the final folder and renamed into place, so that a test process never
    // reads another's half-written fixtures; the first rename wins and the others use it.
    let partial = dir.with_extension(format!("partial-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&partial);
    std::fs::create_dir_all(&partial)
        .map_err(|e| format!("cannot create {}: {e}", partial.display()))?;
    let python = python();
    let output = Command::new(&python)
        .arg(&script)
        .arg(&partial)
        .arg(CASES.to_string())
        .output()
        .map_err(|e| format!("cannot run {}: {e}", python.display()))?;
    if !output.status.success() {
        let _ = std::fs::remove_dir_all(&partial);
        return Err(format!(
            "{} {} failed ({}):\n{}",
            python.display(),
            script.display(),
            output.status,
            String::from_utf8_lossy(&output.stderr)
        ));
    }
    if std::fs::rename(&partial, &dir).is_err() {
        let _ = std::fs::remove_dir_all(&partial);
        if !dir.is_dir() {
            return Err(format!("cannot move the fixtures into {}", dir.display()));
        }
    }
    Ok(Fixtures { dir })
}
