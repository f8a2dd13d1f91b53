//! The report in a real browser: a report built from synthetic data is opened in headless
//! Chromium, which must load it without console errors or blocked requests and find every figure
//! drawn (the page's own check script writes `data-figures-ok` on `<body>`, read back from the
//! dumped DOM).
//!
//! Needs Chromium (`/usr/bin/chromium`, or the path in `FORMATION_CHROMIUM`); CI installs it
//! (`.ci/run`). `FORMATION_SKIP_BROWSER=1` skips the test with a message.
//! `FORMATION_REPORT_SCREENSHOT=/path/shot.png` also saves a screenshot of the page.

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use formation_report::build_report;

/// How long one Chromium run may take.
const BROWSER_TIMEOUT: Duration = Duration::from_secs(120);

fn find_chromium() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("FORMATION_CHROMIUM") {
        return Some(PathBuf::from(path));
    }
    ["/usr/bin/chromium", "/usr/bin/chromium-browser", "/usr/bin/google-chrome"]
        .into_iter()
        .map(PathBuf::from)
        .find(|p| p.exists())
}

/// Output of one headless Chromium run.
struct BrowserRun {
    stdout: String,
    stderr: String,
}

/// Runs headless Chromium with a fresh profile on `url` with the extra `args`.
fn run_chromium(browser: &Path, profile: &Path, args: &[String], url: &str) -> BrowserRun {
    let mut child = Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--enable-logging=stderr",
            "--v=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(args)
        .arg(url)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("could not start {}: {e}", browser.display()));
    let mut stdout_pipe = child.stdout.take().expect("piped stdout");
    let mut stderr_pipe = child.stderr.take().expect("piped stderr");
    let stdout_reader = std::thread::spawn(move || {
        let mut text = String::new();
        stdout_pipe.read_to_string(&mut text).map(|_| text)
    });
    let stderr_reader = std::thread::spawn(move || {
        let mut text = String::new();
        stderr_pipe.read_to_string(&mut text).map(|_| text)
    });
    let started = Instant::now();
    loop {
        if child.try_wait().expect("wait for chromium").is_some() {
            break;
        }
        if started.elapsed() > BROWSER_TIMEOUT {
            let _ = child.kill();
            let _ = child.wait();
            panic!("headless Chromium did not finish within {BROWSER_TIMEOUT:?}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    BrowserRun {
        stdout: stdout_reader.join().expect("stdout reader").unwrap_or_default(),
        stderr: stderr_reader.join().expect("stderr reader").unwrap_or_default(),
    }
}

/// The value of attribute `name` on the dumped `<body>` tag.
fn body_attribute(dom: &str, name: &str) -> Option<String> {
    let body = &dom[dom.find("<body")?..];
    let tag = &body[..body.find('>')?];
    let start = tag.find(&format!("{name}=\""))? + name.len() + 2;
    let end = start + tag[start..].find('"')?;
    Some(tag[start..end].to_owned())
}

/// Console errors, uncaught exceptions and blocked loads in Chromium's log.
fn error_lines(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .filter(|line| {
            let console_error = line.contains("CONSOLE") && (line.contains(":ERROR:") || line.contains("Error"));
            console_error
                || line.contains("Uncaught")
                || line.contains("Refused to")
                || line.contains("Failed to load resource")
        })
        .collect()
}

#[test]
fn report_loads_in_headless_chromium_with_every_figure_drawn() {
    if std::env::var_os("FORMATION_SKIP_BROWSER").is_some_and(|v| v == "1") {
        eprintln!("browser test skipped: FORMATION_SKIP_BROWSER=1");
        return;
    }
    let Some(browser) = find_chromium() else {
        panic!(
            "headless Chromium is needed for the report's browser test but /usr/bin/chromium is missing: \
             run `.ci/run` (installs it) or `apt-get install -y chromium`, or set FORMATION_SKIP_BROWSER=1 to skip"
        );
    };
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    common::write_demo_dir(&data, 40.0);
    let out = dir.path().join("report.html");
    let summary = build_report(&data, &out).expect("report");
    let url = format!("file://{}", out.display());

    let run = run_chromium(&browser, &dir.path().join("profile-dom"), &["--dump-dom".to_owned()], &url);
    let total = body_attribute(&run.stdout, "data-figures-total");
    let ok = body_attribute(&run.stdout, "data-figures-ok");
    let expected = summary.figures.len().to_string();
    assert_eq!(
        total.as_deref(),
        Some(expected.as_str()),
        "the page's check script did not run or saw the wrong number of figures\nstderr:\n{}",
        run.stderr
    );
    assert_eq!(
        ok.as_deref(),
        Some(expected.as_str()),
        "blank or missing figures: {:?}",
        body_attribute(&run.stdout, "data-figures-bad")
    );
    let errors = error_lines(&run.stderr);
    assert!(errors.is_empty(), "browser errors:\n{}", errors.join("\n"));
    // The console is captured (so the absence of errors above means something).
    assert!(
        run.stderr.contains(&format!("formation-report: {expected}/{expected} figures drawn")),
        "the page's console message is missing from Chromium's log:\n{}",
        run.stderr
    );

    if let Some(shot) = std::env::var_os("FORMATION_REPORT_SCREENSHOT") {
        let shot = PathBuf::from(shot);
        run_chromium(
            &browser,
            &dir.path().join("profile-shot"),
            &[format!("--screenshot={}", shot.display()), "--window-size=1280,8000".to_owned(), "--hide-scrollbars".to_owned()],
            &url,
        );
        assert!(shot.exists(), "no screenshot at {}", shot.display());
    }
}
