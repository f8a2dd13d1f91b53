//! Every file and folder a run writes is private to its user, whatever the umask (the
//! reliability issue's "run files are not private"): `formation run`, `formation eval --out`
//! (in-process and over processes), `formation profile` and `formation report` are each started
//! under umask 022, and every entry under their output folder is listed and checked. A writer
//! added later to any of these commands is covered by the listing without a change here.

use std::os::unix::fs::PermissionsExt as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use formation_tests::{ProcessTest, binaries, report_command, run, test_model};

/// The watchdog limit of each test: generous, it only stops a hung test.
const LIMIT: Duration = Duration::from_secs(300);

/// `command` run under umask 022 (the common default, which leaves new files 0644 and folders
/// 0755 unless the writer says otherwise).
fn under_umask_022(command: &Command) -> Command {
    let mut shell = Command::new("sh");
    shell
        .args(["-c", "umask 022 && exec \"$0\" \"$@\""])
        .arg(command.get_program())
        .args(command.get_args());
    for (key, value) in command.get_envs() {
        match value {
            Some(value) => shell.env(key, value),
            None => shell.env_remove(key),
        };
    }
    shell
}

/// Every file and folder under `root` (itself included), with its permission bits.
fn entries_with_modes(root: &Path) -> Vec<(PathBuf, u32)> {
    let mut found = Vec::new();
    let mut pending = vec![root.to_path_buf()];
    while let Some(path) = pending.pop() {
        let meta = std::fs::symlink_metadata(&path).expect("metadata of a listed entry");
        found.push((path.clone(), meta.permissions().mode() & 0o777));
        if meta.is_dir() {
            for entry in std::fs::read_dir(&path).expect("read_dir") {
                pending.push(entry.expect("entry").path());
            }
        }
    }
    found
}

/// Asserts that `root` holds at least `expected` (relative paths) and that nothing under it is
/// readable, writable or searchable by group or others.
fn assert_private(root: &Path, expected: &[&str]) {
    let entries = entries_with_modes(root);
    for name in expected {
        assert!(
            entries.iter().any(|(p, _)| p == &root.join(name)),
            "{name} was written under {}: {entries:#?}",
            root.display()
        );
    }
    let shared: Vec<_> = entries
        .iter()
        .filter(|(_, mode)| mode & 0o077 != 0)
        .map(|(p, mode)| format!("{} {mode:o}", p.display()))
        .collect();
    assert!(
        shared.is_empty(),
        "entries readable by group or others under umask 022: {shared:#?}"
    );
}

/// `formation run` (world, agents, run logs, timing logs, summary, profile) and `formation
/// report` on its output.
#[test]
fn a_runs_files_are_private_under_umask_022() {
    let t = ProcessTest::start("private_run_files", LIMIT);
    let out = t.out();
    let scenario = t.case1(2.0);
    run(
        under_umask_022(&t.formation_run(&scenario, &["--pace-ms", "5"])),
        LIMIT,
    )
    .assert_success();
    t.assert_clean();
    assert_private(
        &out,
        &[
            "summary.json",
            "profile.json",
            "profile.svg",
            "runs/run-0000.json",
        ],
    );

    let report = report_command(&out, &t.path().join("report/index.html"));
    run(under_umask_022(&report), LIMIT).assert_success();
    assert_private(&t.path().join("report"), &["index.html"]);
}

/// `formation eval --out` in-process and over processes, and `formation profile --out`.
#[test]
fn eval_and_profile_files_are_private_under_umask_022() {
    let t = ProcessTest::start("private_eval_files", LIMIT);
    let scenario = t.case1(2.0);
    let eval = |out: &Path, extra: &[&str]| {
        let mut command = Command::new(&binaries().cli);
        command
            .args(["eval", "--controller", "policy", "--runs", "2"])
            .args(["--save-trajectories", "2"])
            .args(extra)
            .arg("--scenario")
            .arg(&scenario)
            .arg("--model")
            .arg(test_model())
            .arg("--out")
            .arg(out);
        command
    };
    let in_process = t.path().join("eval/in-process");
    run(under_umask_022(&eval(&in_process, &[])), LIMIT).assert_success();
    assert_private(
        &t.path().join("eval"),
        &["in-process/summary.json", "in-process/runs/run-0001.json"],
    );

    let processes = t.path().join("eval-processes");
    run(under_umask_022(&eval(&processes, &["--processes"])), LIMIT).assert_success();
    assert_private(&processes, &["summary.json", "runs/run-0000.json"]);

    let profiled = t.path().join("profile");
    let mut profile = Command::new(&binaries().cli);
    profile
        .args(["profile", "--run-id", t.run.as_str()])
        .arg("--scenario")
        .arg(&scenario)
        .arg("--model")
        .arg(test_model())
        .arg("--out")
        .arg(&profiled);
    run(under_umask_022(&profile), LIMIT).assert_success();
    t.assert_clean();
    assert_private(&profiled, &["profile.json"]);
}
