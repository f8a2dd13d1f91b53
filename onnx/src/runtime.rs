//! Finding the ONNX Runtime shared library and starting ONNX Runtime once per process.
//!
//! ort is built with `load-dynamic`: nothing is linked, the library is opened at run time. Left to
//! itself ort looks for an unversioned `libonnxruntime.so` (which the PyPI wheel does not ship) and
//! panics when that fails, so this module finds the file itself ([`ort_library_path`]) and starts
//! the runtime from that exact path, turning every failure into a [`PolicyError`].

use std::ffi::OsStr;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;

use ort::environment::Environment;

use crate::error::PolicyError;

/// Environment variable that names the library explicitly (the same one ort itself reads).
pub const ORT_DYLIB_PATH: &str = "ORT_DYLIB_PATH";

/// The process-wide runtime: the environment, or why it could not start (kept, because ort can
/// only try once: a failed start leaves it in a state where any further use would panic).
static RUNTIME: OnceLock<Result<Environment, (PathBuf, String)>> = OnceLock::new();

/// Where the ONNX Runtime shared library is, in order of preference:
///
/// 1. `$ORT_DYLIB_PATH` (it must exist, else [`PolicyError::LibraryPathMissing`]);
/// 2. the repository's `.venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so.*`
///    (the repository root is the nearest ancestor of the current directory whose `Cargo.toml`
///    declares a `[workspace]`, else the one this crate was built in);
/// 3. the `onnxruntime` package of the `python3` on `PATH`.
///
/// Nothing found gives [`PolicyError::LibraryNotFound`], whose message says how to install it.
pub fn ort_library_path() -> Result<PathBuf, PolicyError> {
    let from_env = std::env::var_os(ORT_DYLIB_PATH);
    let root = repo_root();
    locate_library(from_env.as_deref(), &root, python_onnxruntime_dir)
}

/// The variable ONNX Runtime reads, when it loads, to skip its telemetry store.
pub const ORT_DISABLE_TELEMETRY: &str = "ORT_DISABLE_TELEMETRY";

/// Keeps ONNX Runtime from writing outside the run's own folders: from 1.31 it persists a
/// telemetry device id under `~/.cache/Microsoft/DeveloperTools/.onnxruntime/` and a session file
/// `.ses` in the temporary folder when it loads, whatever the environment's telemetry setting
/// (`with_telemetry(false)` stops only its events), unless `ORT_DISABLE_TELEMETRY` is set. Sets it
/// for this process and the processes it starts, unless the user set it.
///
/// Call it first thing in `main`, before the process starts any thread: changing the environment
/// while another thread reads it is undefined behaviour.
pub fn disable_telemetry_before_threads() {
    if std::env::var_os(ORT_DISABLE_TELEMETRY).is_none() {
        #[allow(unsafe_code)]
        // SAFETY: called at the start of `main`, before this process starts a thread, so no other
        // thread reads or writes the environment meanwhile.
        unsafe {
            std::env::set_var(ORT_DISABLE_TELEMETRY, "1");
        }
    }
}

/// Starts ONNX Runtime from `library` for this process (telemetry off). Only the first call in a
/// process has an effect; later calls return its outcome, whatever `library` they name.
pub fn init_runtime(library: &Path) -> Result<(), PolicyError> {
    runtime_from(library).map(|_| ())
}

/// The process's ONNX Runtime environment, started from [`ort_library_path`] on first use.
pub(crate) fn environment() -> Result<&'static Environment, PolicyError> {
    match RUNTIME.get() {
        Some(started) => as_policy_result(started),
        // The path is looked up outside the lock: a library not (yet) installed is not cached.
        None => runtime_from(&ort_library_path()?),
    }
}

fn runtime_from(library: &Path) -> Result<&'static Environment, PolicyError> {
    as_policy_result(RUNTIME.get_or_init(|| start_runtime(library)))
}

fn as_policy_result(
    started: &'static Result<Environment, (PathBuf, String)>,
) -> Result<&'static Environment, PolicyError> {
    started
        .as_ref()
        .map_err(|(path, reason)| PolicyError::RuntimeLoad {
            path: path.clone(),
            reason: reason.clone(),
        })
}

fn start_runtime(library: &Path) -> Result<Environment, (PathBuf, String)> {
    let fail = |reason: String| (library.to_path_buf(), reason);
    if !library.is_file() {
        return Err(fail("no such file".to_owned()));
    }
    // ort asserts on some malformed libraries instead of returning an error: contain that too.
    let started = catch_unwind(AssertUnwindSafe(|| {
        ort::init_from(library)
            .map_err(|e| e.to_string())?
            .with_name("formation")
            .with_telemetry(false)
            .build()
            .map_err(|e| e.to_string())
    }));
    match started {
        Ok(result) => result.map_err(fail),
        Err(panic) => Err(fail(panic_message(panic.as_ref()))),
    }
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    if let Some(text) = panic.downcast_ref::<&str>() {
        format!("panicked: {text}")
    } else if let Some(text) = panic.downcast_ref::<String>() {
        format!("panicked: {text}")
    } else {
        "panicked".to_owned()
    }
}

/// The search behind [`ort_library_path`], with its inputs passed in so it can be tested.
fn locate_library(
    from_env: Option<&OsStr>,
    repo_root: &Path,
    python_package_dir: impl FnOnce() -> Option<PathBuf>,
) -> Result<PathBuf, PolicyError> {
    if let Some(value) = from_env.filter(|v| !v.is_empty()) {
        let path = PathBuf::from(value);
        return if path.is_file() {
            Ok(path)
        } else {
            Err(PolicyError::LibraryPathMissing { path })
        };
    }
    let venv_lib = repo_root.join(".venv").join("lib");
    let mut searched = vec![
        format!("{ORT_DYLIB_PATH} (unset)"),
        format!(
            "{}/python3*/site-packages/onnxruntime/capi",
            venv_lib.display()
        ),
    ];
    if let Some(found) = venv_site_packages(&venv_lib)
        .into_iter()
        .find_map(|site| library_in_package(&site.join("onnxruntime")))
    {
        return Ok(found);
    }
    match python_package_dir() {
        Some(package) => {
            searched.push(format!(
                "{}/capi (python3's onnxruntime)",
                package.display()
            ));
            if let Some(found) = library_in_package(&package) {
                return Ok(found);
            }
        }
        None => searched.push("python3 -c 'import onnxruntime' (not importable)".to_owned()),
    }
    Err(PolicyError::LibraryNotFound { searched })
}

/// `site-packages` directories of a venv's `lib/python3*`, newest Python first.
fn venv_site_packages(venv_lib: &Path) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(venv_lib)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|entry| entry.file_name().to_string_lossy().starts_with("python3"))
        .map(|entry| entry.path().join("site-packages"))
        .filter(|dir| dir.is_dir())
        .collect();
    found.sort();
    found.reverse();
    found
}

/// The shared library inside an installed `onnxruntime` Python package (`capi/libonnxruntime.so.*`).
fn library_in_package(package: &Path) -> Option<PathBuf> {
    let mut candidates: Vec<PathBuf> = std::fs::read_dir(package.join("capi"))
        .ok()?
        .flatten()
        .filter(|entry| is_runtime_library_name(&entry.file_name().to_string_lossy()))
        .map(|entry| entry.path())
        .filter(|path| path.is_file())
        .collect();
    candidates.sort();
    candidates.pop()
}

/// `libonnxruntime.so`, `libonnxruntime.so.1.31.1` or `libonnxruntime.1.31.1.dylib`, but not
/// `libonnxruntime_providers_shared.so`.
fn is_runtime_library_name(name: &str) -> bool {
    name == "libonnxruntime.so"
        || name.starts_with("libonnxruntime.so.")
        || (name.starts_with("libonnxruntime.") && name.ends_with(".dylib"))
}

/// The nearest ancestor of the current directory whose `Cargo.toml` declares a workspace, else
/// the workspace this crate was built in.
fn repo_root() -> PathBuf {
    let build_root = || Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let Ok(cwd) = std::env::current_dir() else {
        return build_root();
    };
    cwd.ancestors()
        .find(|dir| {
            std::fs::read_to_string(dir.join("Cargo.toml"))
                .is_ok_and(|text| text.contains("[workspace]"))
        })
        .map_or_else(build_root, Path::to_path_buf)
}

/// The directory of the `onnxruntime` package of the `python3` on `PATH`, if it imports.
fn python_onnxruntime_dir() -> Option<PathBuf> {
    let output = Command::new("python3")
        .args([
            "-c",
            "import onnxruntime,os;print(os.path.dirname(onnxruntime.__file__))",
        ])
        .stdin(Stdio::null())
        .stderr(Stdio::null())
        .output()
        .ok()?;
    if !output.status.success() {
        return None;
    }
    let dir = String::from_utf8(output.stdout).ok()?;
    let dir = dir.trim();
    (!dir.is_empty()).then(|| PathBuf::from(dir))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn touch(path: &Path) {
        std::fs::create_dir_all(path.parent().expect("has a parent")).expect("mkdir");
        std::fs::write(path, b"not really a library").expect("write");
    }

    #[test]
    fn runtime_library_names() {
        assert!(is_runtime_library_name("libonnxruntime.so.1.31.1"));
        assert!(is_runtime_library_name("libonnxruntime.so"));
        assert!(is_runtime_library_name("libonnxruntime.1.31.1.dylib"));
        assert!(!is_runtime_library_name(
            "libonnxruntime_providers_shared.so"
        ));
        assert!(!is_runtime_library_name("onnxruntime_pybind11_state.so"));
    }

    #[test]
    fn env_variable_wins_and_must_exist() {
        let dir = tempfile::tempdir().expect("tempdir");
        let lib = dir.path().join("custom.so");
        touch(&lib);
        let found = locate_library(Some(lib.as_os_str()), dir.path(), || {
            panic!("python not asked")
        });
        assert_eq!(found.expect("env path exists"), lib);

        let missing = dir.path().join("nope.so");
        match locate_library(Some(missing.as_os_str()), dir.path(), || None) {
            Err(PolicyError::LibraryPathMissing { path }) => assert_eq!(path, missing),
            other => panic!("expected LibraryPathMissing, got {other:?}"),
        }
    }

    #[test]
    fn venv_library_is_found_and_empty_env_is_ignored() {
        let root = tempfile::tempdir().expect("tempdir");
        let capi = root
            .path()
            .join(".venv/lib/python3.11/site-packages/onnxruntime/capi");
        touch(&capi.join("libonnxruntime_providers_shared.so"));
        touch(&capi.join("libonnxruntime.so.1.31.1"));
        let found = locate_library(Some(OsStr::new("")), root.path(), || {
            panic!("python not asked")
        });
        assert_eq!(
            found.expect("venv library"),
            capi.join("libonnxruntime.so.1.31.1")
        );
    }

    #[test]
    fn python_package_is_the_last_resort_and_failure_explains_the_fix() {
        let root = tempfile::tempdir().expect("tempdir");
        let package = root.path().join("elsewhere/onnxruntime");
        touch(&package.join("capi/libonnxruntime.so.1.31.1"));
        let found = locate_library(None, root.path(), || Some(package.clone()));
        assert_eq!(
            found.expect("python's library"),
            package.join("capi/libonnxruntime.so.1.31.1")
        );

        let err = locate_library(None, root.path(), || None).expect_err("nothing anywhere");
        assert!(
            matches!(err, PolicyError::LibraryNotFound { ref searched } if searched.len() == 3)
        );
        let message = err.to_string();
        assert!(message.contains("bash .ci/setup-python"), "{message}");
        assert!(
            message.contains("ORT_DYLIB_PATH=/path/to/libonnxruntime.so.1.31.1"),
            "{message}"
        );
    }

    #[test]
    fn a_missing_library_file_is_a_load_error_not_a_panic() {
        let (path, reason) = start_runtime(Path::new("/nonexistent/libonnxruntime.so.1.31.1"))
            .expect_err("nothing to load");
        assert_eq!(path, Path::new("/nonexistent/libonnxruntime.so.1.31.1"));
        assert_eq!(reason, "no such file");
    }
}
