//! The report in a real browser: a report built from synthetic data is opened in headless
//! Chromium, which must load it without console errors or blocked requests and find every figure
//! drawn (the page's own check script writes `data-figures-ok` on `<body>`, read back from the
//! dumped DOM).
//!
//! Needs Chromium (`/usr/bin/chromium`, or the path in `FORMATION_CHROMIUM`); CI installs it
//! (`.ci/run`); without it the test fails with the fix.
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
    let candidates: Vec<PathBuf> = match std::env::var_os("FORMATION_CHROMIUM") {
        Some(path) => vec![PathBuf::from(path)],
        None => [
            "/usr/bin/chromium",
            "/usr/bin/chromium-browser",
            "/usr/bin/google-chrome",
        ]
        .into_iter()
        .map(PathBuf::from)
        .collect(),
    };
    candidates.into_iter().find(|p| p.is_file())
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
        stdout: stdout_reader
            .join()
            .expect("stdout reader")
            .unwrap_or_default(),
        stderr: stderr_reader
            .join()
            .expect("stderr reader")
            .unwrap_or_default(),
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

/// Console messages other than the page's own check line (Chromium logs `console.error`, uncaught
/// exceptions and blocked loads all as `CONSOLE` lines), and uncaught exceptions.
fn unexpected_console_lines(stderr: &str) -> Vec<&str> {
    stderr
        .lines()
        .filter(|line| {
            (line.contains("CONSOLE") && !line.contains("\"formation-report: "))
                || line.contains("Uncaught")
        })
        .collect()
}

/// The value of attribute `name` on the dumped `<html>` tag.
fn html_attribute(dom: &str, name: &str) -> Option<String> {
    let html = &dom[dom.find("<html")?..];
    let tag = &html[..html.find('>')?];
    let start = tag.find(&format!("{name}=\""))? + name.len() + 2;
    let end = start + tag[start..].find('"')?;
    Some(tag[start..end].to_owned())
}

/// Headless Chromium; its absence fails the test with the fix (no test passes by skipping).
fn chromium() -> PathBuf {
    find_chromium().unwrap_or_else(|| {
        panic!(
            "headless Chromium is needed for the report's browser test but /usr/bin/chromium (or \
             $FORMATION_CHROMIUM) is missing: run `.ci/run` (installs it) or `apt-get install -y chromium`"
        )
    })
}

#[test]
fn report_loads_in_headless_chromium_with_every_figure_drawn() {
    let browser = chromium();
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    common::write_demo_dir(&data, 40.0);
    let out = dir.path().join("report.html");
    let summary = build_report(&data, &out).expect("report");
    let url = format!("file://{}", out.display());

    let run = run_chromium(
        &browser,
        &dir.path().join("profile-dom"),
        &["--dump-dom".to_owned()],
        &url,
    );
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
    let errors = unexpected_console_lines(&run.stderr);
    assert!(errors.is_empty(), "browser console:\n{}", errors.join("\n"));
    assert_eq!(
        html_attribute(&run.stdout, "data-page-errors"),
        None,
        "errors recorded by the page"
    );
    // The console is captured (so the absence of errors above means something).
    assert!(
        run.stderr.contains(&format!(
            "formation-report: {expected}/{expected} figures drawn"
        )),
        "the page's console message is missing from Chromium's log:\n{}",
        run.stderr
    );

    if let Some(shot) = std::env::var_os("FORMATION_REPORT_SCREENSHOT") {
        let shot = PathBuf::from(shot);
        run_chromium(
            &browser,
            &dir.path().join("profile-shot"),
            &[
                format!("--screenshot={}", shot.display()),
                "--window-size=1280,8000".to_owned(),
                "--hide-scrollbars".to_owned(),
            ],
            &url,
        );
        assert!(shot.exists(), "no screenshot at {}", shot.display());
    }
}

/// The checks above can fail: a page with a blank figure, a script error and a blocked network
/// load is caught by each of them.
#[test]
fn the_browser_checks_catch_a_broken_page() {
    let browser = chromium();
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    common::write_demo_dir(&data, 6.0);
    let out = dir.path().join("report.html");
    let summary = build_report(&data, &out).expect("report");
    let html = std::fs::read_to_string(&out).expect("html");
    // Blank the first figure's drawing, load an image from the network, throw.
    let first_svg = html.find("<svg ").expect("an svg");
    let first_svg_end =
        first_svg + html[first_svg..].find("</svg>").expect("svg end") + "</svg>".len();
    let broken = format!(
        "{}<svg width=\"10\" height=\"10\"></svg>{}",
        &html[..first_svg],
        &html[first_svg_end..]
    )
    .replace(
        "</main>",
        "<img src=\"https://example.invalid/x.png\"><script>throw new Error('boom')</script></main>",
    );
    let broken_path = dir.path().join("broken.html");
    std::fs::write(&broken_path, broken).expect("write");
    let run = run_chromium(
        &browser,
        &dir.path().join("profile-broken"),
        &["--dump-dom".to_owned()],
        &format!("file://{}", broken_path.display()),
    );
    let total = summary.figures.len();
    assert_eq!(
        body_attribute(&run.stdout, "data-figures-total"),
        Some(total.to_string())
    );
    assert_eq!(
        body_attribute(&run.stdout, "data-figures-ok"),
        Some((total - 1).to_string()),
        "blank figure found"
    );
    let console = unexpected_console_lines(&run.stderr).join("\n");
    assert!(
        console.contains("boom"),
        "uncaught error logged:\n{}",
        run.stderr
    );
    assert!(
        console.contains("example.invalid"),
        "blocked load logged:\n{}",
        run.stderr
    );
    let page_errors = html_attribute(&run.stdout, "data-page-errors").unwrap_or_default();
    assert!(
        page_errors.contains("boom") && page_errors.contains("example.invalid"),
        "{page_errors}"
    );
}
