//! A bad `ORT_DYLIB_PATH` must give an error, never a panic.
//!
//! ONNX Runtime starts once per process, so each case re-runs this test binary as a child
//! process with the variable set, executing only [`child_loads_a_model`] (ignored in normal runs).

use std::path::Path;
use std::process::Command;

use formation_onnx::{OnnxPolicy, PolicyError, ort_library_path};

/// Set in the child: what the child should expect (`missing` or `not-a-library`).
const EXPECT_VAR: &str = "FORMATION_ONNX_CHILD_EXPECT";

/// Runs the child with `ORT_DYLIB_PATH=library` and returns its combined output.
fn run_child(library: &Path, expect: &str, model: &Path) -> String {
    let exe = std::env::current_exe().expect("test binary path");
    let output = Command::new(exe)
        .args([
            "--exact",
            "child_loads_a_model",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("ORT_DYLIB_PATH", library)
        .env(EXPECT_VAR, expect)
        .env("FORMATION_ONNX_CHILD_MODEL", model)
        .output()
        .expect("re-run the test binary");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(output.status.success(), "child failed:\n{text}");
    assert!(text.contains("1 passed"), "the child test ran:\n{text}");
    text
}

#[test]
fn a_file_that_is_not_a_library_is_a_runtime_load_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let library = dir.path().join("libonnxruntime.so.1.31.1");
    std::fs::write(&library, b"\x7fELF but not really").expect("write");
    let model = dir.path().join("policy.onnx");
    std::fs::write(&model, b"never parsed: the runtime fails first").expect("write");
    let text = run_child(&library, "not-a-library", &model);
    assert!(text.contains("could not start ONNX Runtime"), "{text}");
}

#[test]
fn a_missing_file_is_named_in_the_error() {
    let dir = tempfile::tempdir().expect("tempdir");
    let model = dir.path().join("policy.onnx");
    std::fs::write(&model, b"never parsed").expect("write");
    let text = run_child(&dir.path().join("gone.so"), "missing", &model);
    assert!(text.contains("gone.so"), "{text}");
}

/// The child side: loads a model under the inherited `ORT_DYLIB_PATH` and checks the error.
#[test]
#[ignore = "run as a child process by the other tests in this file"]
fn child_loads_a_model() {
    let Ok(expect) = std::env::var(EXPECT_VAR) else {
        return;
    };
    let model = std::env::var_os("FORMATION_ONNX_CHILD_MODEL").expect("model path from the parent");
    let library = std::env::var_os("ORT_DYLIB_PATH").expect("library path from the parent");
    let err = OnnxPolicy::load(Path::new(&model)).expect_err("a bad library cannot load a model");
    println!("error: {err}");
    match (expect.as_str(), &err) {
        ("missing", PolicyError::LibraryPathMissing { path }) => {
            assert_eq!(path.as_os_str(), library)
        }
        ("not-a-library", PolicyError::RuntimeLoad { path, reason }) => {
            assert_eq!(path.as_os_str(), library);
            assert!(!reason.is_empty());
            // The failure is remembered: a second load reports it again instead of panicking in ort.
            let again = OnnxPolicy::load(Path::new(&model)).expect_err("still no runtime");
            assert!(
                matches!(again, PolicyError::RuntimeLoad { .. }),
                "{again:?}"
            );
        }
        _ => panic!("expected a {expect} error, got {err:?}"),
    }
    if expect == "missing" {
        assert!(matches!(
            ort_library_path(),
            Err(PolicyError::LibraryPathMissing { .. })
        ));
    }
}
