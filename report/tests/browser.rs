//! The report in a real browser: a report built from synthetic data is opened in headless
//! Chromium, which must load it without console errors or blocked requests and find every figure
//! drawn (the page's own check script writes `data-figures-ok` on `<body>`, read back from the
//! dumped DOM).
//!
//! Needs Chromium (`/usr/bin/chromium`, or the path in `FORMATION_CHROMIUM`); `scripts/test-all`
//! installs it (`scripts/setup-system`); without it the test fails with the fix.
//! `FORMATION_REPORT_SCREENSHOT=/path/shot.png` also saves a screenshot of the page.

mod common;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use formation_report::{ReportSummary, build_report};

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

/// Writes `html` as `dir/file` and runs headless Chromium on it with a fresh profile
/// `dir/profile`, dumping the page's DOM after its scripts ran.
fn dump_written_page(
    browser: &Path,
    dir: &Path,
    file: &str,
    html: &str,
    profile: &str,
) -> BrowserRun {
    let path = dir.join(file);
    std::fs::write(&path, html).expect("write");
    run_chromium(
        browser,
        &dir.join(profile),
        &["--dump-dom".to_owned()],
        &format!("file://{}", path.display()),
    )
}

/// The value of attribute `name` on the first dumped tag that starts with `opening`.
fn tag_attribute(dom: &str, opening: &str, name: &str) -> Option<String> {
    let from = &dom[dom.find(opening)?..];
    let tag = &from[..from.find('>')?];
    let start = tag.find(&format!(" {name}=\""))? + name.len() + 3;
    let end = start + tag[start..].find('"')?;
    Some(tag[start..end].to_owned())
}

/// The value of attribute `name` on the dumped `<body>` tag.
fn body_attribute(dom: &str, name: &str) -> Option<String> {
    tag_attribute(dom, "<body", name)
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
    tag_attribute(dom, "<html", name)
}

/// Headless Chromium; its absence fails the test with the fix (no test passes by skipping).
fn chromium() -> PathBuf {
    find_chromium().unwrap_or_else(|| {
        panic!(
            "headless Chromium is needed for the report's browser test but /usr/bin/chromium (or \
             $FORMATION_CHROMIUM) is missing: run `bash scripts/setup-system` as root (installs \
             it) or `apt-get install -y chromium`"
        )
    })
}

#[test]
fn report_loads_in_headless_chromium_with_every_figure_drawn() {
    let browser = chromium();
    let (dir, out, summary) = report_of(|data| {
        common::write_demo_dir(data, 40.0);
    });
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
    // One player per drawn run (the three cases).
    assert_eq!(
        body_attribute(&run.stdout, "data-players"),
        Some(summary.runs_drawn.to_string())
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
    let (dir, out, summary) = report_of(|data| {
        common::write_demo_dir(data, 6.0);
    });
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
    let run = dump_written_page(
        &browser,
        dir.path(),
        "broken.html",
        &broken,
        "profile-broken",
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

/// An RGBA image decoded from a PNG file.
struct Image {
    width: usize,
    height: usize,
    rgba: Vec<u8>,
}

impl Image {
    fn pixel(&self, x: usize, y: usize) -> [u8; 4] {
        let at = 4 * (y * self.width + x);
        [
            self.rgba[at],
            self.rgba[at + 1],
            self.rgba[at + 2],
            self.rgba[at + 3],
        ]
    }
}

/// Decodes the 8-bit RGB or RGBA, non-interlaced PNG files Chromium's `--screenshot` writes.
fn decode_png(path: &Path) -> Image {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("read {}: {e}", path.display()));
    assert_eq!(
        &bytes[..8],
        b"\x89PNG\r\n\x1a\n",
        "not a PNG: {}",
        path.display()
    );
    let (mut at, mut header, mut compressed) = (8, None, Vec::new());
    while at + 8 <= bytes.len() {
        let len = u32::from_be_bytes(bytes[at..at + 4].try_into().expect("4 bytes")) as usize;
        let kind = &bytes[at + 4..at + 8];
        let body = &bytes[at + 8..at + 8 + len];
        match kind {
            b"IHDR" => header = Some(body.to_vec()),
            b"IDAT" => compressed.extend_from_slice(body),
            _ => {}
        }
        at += 12 + len;
    }
    let header = header.expect("IHDR");
    let width = u32::from_be_bytes(header[0..4].try_into().expect("4 bytes")) as usize;
    let height = u32::from_be_bytes(header[4..8].try_into().expect("4 bytes")) as usize;
    let channels = match (header[8], header[9], header[12]) {
        (8, 6, 0) => 4,
        (8, 2, 0) => 3,
        other => panic!("unsupported PNG (bit depth, colour type, interlace) {other:?}"),
    };
    let mut raw = Vec::new();
    flate2::read::ZlibDecoder::new(compressed.as_slice())
        .read_to_end(&mut raw)
        .expect("inflate PNG");
    let stride = width * channels;
    let mut pixels = vec![0u8; stride * height];
    for y in 0..height {
        let filter = raw[y * (stride + 1)];
        let line = &raw[y * (stride + 1) + 1..(y + 1) * (stride + 1)];
        for x in 0..stride {
            let a = if x >= channels {
                pixels[y * stride + x - channels]
            } else {
                0
            };
            let b = if y > 0 {
                pixels[(y - 1) * stride + x]
            } else {
                0
            };
            let c = if x >= channels && y > 0 {
                pixels[(y - 1) * stride + x - channels]
            } else {
                0
            };
            let predicted = match filter {
                0 => 0,
                1 => a,
                2 => b,
                3 => ((u16::from(a) + u16::from(b)) / 2) as u8,
                4 => {
                    let p = i16::from(a) + i16::from(b) - i16::from(c);
                    let (pa, pb, pc) = (
                        (p - i16::from(a)).abs(),
                        (p - i16::from(b)).abs(),
                        (p - i16::from(c)).abs(),
                    );
                    if pa <= pb && pa <= pc {
                        a
                    } else if pb <= pc {
                        b
                    } else {
                        c
                    }
                }
                other => panic!("bad PNG filter {other}"),
            };
            pixels[y * stride + x] = line[x].wrapping_add(predicted);
        }
    }
    let rgba = if channels == 4 {
        pixels
    } else {
        pixels
            .chunks(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect()
    };
    Image {
        width,
        height,
        rgba,
    }
}

/// The value of attribute `name` on the dumped `<figure class="player" ...>` tag.
fn player_attribute(dom: &str, name: &str) -> Option<String> {
    tag_attribute(dom, "<figure class=\"player\"", name)
}

/// `x,y;x,y` → points.
fn parse_points(text: &str) -> Vec<(f64, f64)> {
    text.split(';')
        .map(|p| {
            let (x, y) = p.split_once(',').expect("x,y");
            (x.parse().expect("x"), y.parse().expect("y"))
        })
        .collect()
}

/// The arguments that make the DOM dump and the screenshot of one page lay it out alike.
fn window_args(width: u32, height: u32) -> Vec<String> {
    vec![
        format!("--window-size={width},{height}"),
        "--force-device-scale-factor=1".to_owned(),
        "--hide-scrollbars".to_owned(),
    ]
}

/// Runs headless Chromium on `url` with a fresh `profile` in a window of `width` × `height`,
/// laid out as a screenshot of it would be ([`window_args`]), dumping the page's DOM after its
/// scripts ran.
fn dump_dom_in_window(
    browser: &Path,
    profile: &Path,
    (width, height): (u32, u32),
    url: &str,
) -> BrowserRun {
    let mut args = window_args(width, height);
    args.push("--dump-dom".to_owned());
    run_chromium(browser, profile, &args, url)
}

/// The window height of the player's screenshots: the whole page fits, so nothing scrolls.
const PAGE_HEIGHT: u32 = 5000;

/// The player shown at `time`: the dumped DOM (with the robots' screen positions) and a
/// screenshot of the window.
fn player_at(browser: &Path, dir: &Path, html: &Path, time: f64) -> (String, Image) {
    let url = format!("file://{}#player-t={time}", html.display());
    let dom = dump_dom_in_window(
        browser,
        &dir.join(format!("profile-dom-{time}")),
        (1300, PAGE_HEIGHT),
        &url,
    );
    let errors = unexpected_console_lines(&dom.stderr);
    assert!(errors.is_empty(), "browser console:\n{}", errors.join("\n"));
    let shot = dir.join(format!("player-{time}.png"));
    let mut args = window_args(1300, PAGE_HEIGHT);
    args.push(format!("--screenshot={}", shot.display()));
    run_chromium(
        browser,
        &dir.join(format!("profile-shot-{time}")),
        &args,
        &url,
    );
    assert!(shot.exists(), "no screenshot at {}", shot.display());
    if let Some(keep) = std::env::var_os("FORMATION_PLAYER_SCREENSHOTS") {
        let keep = PathBuf::from(keep);
        std::fs::create_dir_all(&keep).expect("mkdir");
        std::fs::copy(&shot, keep.join(format!("player-{time}.png"))).expect("copy");
        std::fs::copy(html, keep.join("report.html")).expect("copy");
    }
    (dom.stdout, decode_png(&shot))
}

/// Pixels in the square of half-side `r` around `(x, y)` that differ between `a` and `b`.
fn differing_pixels(a: &Image, b: &Image, (x, y): (f64, f64), r: i64) -> usize {
    let mut count = 0;
    for dy in -r..=r {
        for dx in -r..=r {
            let (px, py) = (x.round() as i64 + dx, y.round() as i64 + dy);
            if px < 0 || py < 0 || px as usize >= a.width || py as usize >= a.height {
                continue;
            }
            if a.pixel(px as usize, py as usize) != b.pixel(px as usize, py as usize) {
                count += 1;
            }
        }
    }
    count
}

/// The report of the inputs `write_data` writes into `data/` of a temp folder (kept while the
/// guard lives): the folder, the page (`report.html` beside `data/`) and what was written.
fn report_of(write_data: impl FnOnce(&Path)) -> (tempfile::TempDir, PathBuf, ReportSummary) {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("data");
    write_data(&data);
    let out = dir.path().join("report.html");
    let summary = build_report(&data, &out).expect("report");
    (dir, out, summary)
}

/// A report of one 16-robot, 60 s run in a temp folder (kept while the guard lives).
fn sixteen_robot_report() -> (tempfile::TempDir, std::path::PathBuf) {
    let (dir, out, _) = report_of(|data| common::write_team_dir(data, 16, 60.0));
    (dir, out)
}

/// Issue 39: the page opens with the player's time slider at the first frame, where its clock
/// says it is (a range input left alone starts at its middle).
#[test]
fn the_players_slider_starts_at_the_time_its_clock_shows() {
    let browser = chromium();
    let (dir, out) = sixteen_robot_report();
    let url = format!("file://{}", out.display());
    let profile = dir.path().join("profile-start");
    let dom = dump_dom_in_window(&browser, &profile, (1300, PAGE_HEIGHT), &url).stdout;
    assert_eq!(body_attribute(&dom, "data-players").as_deref(), Some("1"));
    let time = player_attribute(&dom, "data-player-time").expect("time");
    assert_eq!(time, "0.000");
    assert_eq!(
        player_attribute(&dom, "data-player-slider").as_deref(),
        Some(time.as_str())
    );
    // At a later time both move together.
    let (later, _) = player_at(&browser, dir.path(), &out, 5.0);
    assert_eq!(
        player_attribute(&later, "data-player-slider").as_deref(),
        Some("5.000")
    );
}

/// The player in Chromium: at two times of a 16-robot run the screenshots differ where the
/// robots were and moved away from, the robots are drawn where the page says, and nothing outside
/// the player changes.
#[test]
fn the_player_draws_the_robots_where_they_are_at_two_times() {
    let browser = chromium();
    let (dir, out) = sixteen_robot_report();

    let (dom_a, shot_a) = player_at(&browser, dir.path(), &out, 5.0);
    let (dom_b, shot_b) = player_at(&browser, dir.path(), &out, 40.0);
    assert_eq!(body_attribute(&dom_a, "data-players").as_deref(), Some("1"));
    assert_eq!(
        player_attribute(&dom_a, "data-player-time").as_deref(),
        Some("5.000")
    );
    assert_eq!(
        player_attribute(&dom_b, "data-player-time").as_deref(),
        Some("40.000")
    );
    let robots_a = parse_points(&player_attribute(&dom_a, "data-player-robots").expect("robots"));
    let robots_b = parse_points(&player_attribute(&dom_b, "data-player-robots").expect("robots"));
    assert_eq!((robots_a.len(), robots_b.len()), (16, 16));
    let box_a = player_attribute(&dom_a, "data-player-box").expect("box");
    assert_eq!(
        Some(&box_a),
        player_attribute(&dom_b, "data-player-box").as_ref()
    );
    let bounds: Vec<f64> = box_a
        .split(',')
        .map(|v| v.parse().expect("number"))
        .collect();
    assert!(
        bounds[3] < f64::from(PAGE_HEIGHT) - 100.0,
        "the player lies inside the window: {box_a}"
    );
    assert_eq!((shot_a.width, shot_a.height), (shot_b.width, shot_b.height));

    let white = [255, 255, 255, 255];
    let mut moved_robots = 0;
    for (k, (&a, &b)) in robots_a.iter().zip(&robots_b).enumerate() {
        // Drawn where the page says, at each time.
        assert_ne!(
            shot_a.pixel(a.0 as usize, a.1 as usize),
            white,
            "robot {k} at {a:?} (5 s)"
        );
        assert_ne!(
            shot_b.pixel(b.0 as usize, b.1 as usize),
            white,
            "robot {k} at {b:?} (40 s)"
        );
        // Where a robot moved on screen, the two images differ around its place at either time.
        if (a.0 - b.0).hypot(a.1 - b.1) > 20.0 {
            moved_robots += 1;
            for at in [a, b] {
                let changed = differing_pixels(&shot_a, &shot_b, at, 4);
                assert!(
                    changed >= 20,
                    "robot {k}: only {changed} of 81 pixels around {at:?} changed"
                );
            }
        }
    }
    assert!(
        moved_robots >= 8,
        "only {moved_robots} robots moved on screen"
    );
    // Outside the player nothing changed.
    let (left, top, right, bottom) = (bounds[0], bounds[1], bounds[2], bounds[3]);
    let mut outside_changed = 0;
    let mut outside = 0;
    for y in 0..shot_a.height {
        for x in 0..shot_a.width {
            let (fx, fy) = (x as f64, y as f64);
            if fx >= left - 1.0 && fx <= right + 1.0 && fy >= top - 1.0 && fy <= bottom + 1.0 {
                continue;
            }
            outside += 1;
            if shot_a.pixel(x, y) != shot_b.pixel(x, y) {
                outside_changed += 1;
            }
        }
    }
    assert!(
        outside > 10_000,
        "too little of the page outside the player: {outside}"
    );
    assert_eq!(outside_changed, 0, "pixels outside the player changed");
}

/// The player's frame rate on a 16-robot run of 60 s in Chromium (`#player-bench`: 300 frames,
/// each drawn and rasterised), printed; the page must measure a positive rate.
#[test]
fn the_players_frame_rate_on_sixteen_robots_is_measured() {
    let browser = chromium();
    let (dir, out) = sixteen_robot_report();
    let run = dump_dom_in_window(
        &browser,
        &dir.path().join("profile-bench"),
        (1300, 900),
        &format!("file://{}#player-bench", out.display()),
    );
    let fps: f64 = body_attribute(&run.stdout, "data-player-fps")
        .unwrap_or_else(|| panic!("no frame rate measured\nstderr:\n{}", run.stderr))
        .parse()
        .expect("a number");
    let bench = body_attribute(&run.stdout, "data-player-bench").unwrap_or_default();
    println!("player: {fps:.1} frames/s ({bench})");
    assert!(fps > 0.0 && fps.is_finite(), "{fps}");
    assert!(
        bench.starts_with("300 frames of 16 robots over 60.0 s"),
        "{bench}"
    );
}

/// Text of every `<text>` element of an SVG.
fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|rest| {
            let body = &rest[rest.find('>')? + 1..];
            Some(body[..body.find("</text>")?].trim().to_owned())
        })
        .collect()
}

/// Seen in Chromium at 1300 px: the scaling table's last column was clipped, and a scaling
/// section with one team size drew its axis from 15.6 to 16.4 robots. Now every table fits its
/// box at 1300 px, and the team-size axis is labelled with whole team sizes only.
#[test]
fn at_1300_px_the_tables_fit_and_one_team_size_gets_whole_ticks() {
    use formation_schema::{Quantiles, ScalingRow, ScalingTable};
    let browser = chromium();
    let q = |median: f64| Quantiles {
        min: median - 3.0,
        q1: median - 1.25,
        median,
        q3: median + 2.25,
        max: median + 5.0,
        count: 100,
    };
    let row = |controller: &str, model: Option<&str>| ScalingRow {
        controller: controller.into(),
        model: model.map(str::to_owned),
        robots: 16,
        neighbours: "gabriel".into(),
        runs: 100,
        success_rate_5: 0.79,
        success_rate_10: 0.92,
        anchor_success_rate: 1.0,
        convergence_s: Some(q(12.35)),
        rel_formation_error: Some(q(0.0312)),
        max_edge_window_error: Some(q(0.061)),
        collisions: 12,
        team_size: None,
        goal_speed: None,
        model_input: None,
    };
    let table = ScalingTable {
        scenario: "teams-generalist".into(),
        seed: 7,
        duration_s: 60.0,
        rows: vec![
            row("expert", None),
            row("policy", Some("teams-generalist-policy-3f9a1c2e")),
        ],
    };
    let (dir, out, summary) = report_of(|data| {
        common::write_demo_dir(data, 6.0);
        common::write_file(&data.join("scaling.json"), &table);
    });

    let run = dump_dom_in_window(
        &browser,
        &dir.path().join("profile-1300"),
        (1300, 1000),
        &format!("file://{}", out.display()),
    );
    assert_eq!(
        body_attribute(&run.stdout, "data-tables-clipped").as_deref(),
        Some("none"),
        "a table is wider than its box at 1300 px (index: scroll width > box width)"
    );

    let scaling_svg = summary
        .figures
        .iter()
        .find(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with("scaling"))
        })
        .expect("the scaling figure");
    let texts = svg_texts(&std::fs::read_to_string(scaling_svg).expect("svg"));
    assert!(
        texts.iter().any(|t| t == "16"),
        "16 robots labelled: {texts:?}"
    );
    for fraction in ["15.6", "15.8", "16.2", "16.4", "15.5", "16.5"] {
        assert!(
            !texts.iter().any(|t| t == fraction),
            "tick {fraction}: {texts:?}"
        );
    }
    // Both axes' team-size labels are whole numbers, around the one size.
    let team_sizes: Vec<&String> = texts
        .iter()
        .filter(|t| matches!(t.as_str(), "15" | "16" | "17"))
        .collect();
    assert!(team_sizes.len() >= 2, "{texts:?}");
}

/// Measures, in the loaded page, the legend labels of every run's error, wheel and trajectory
/// figure (the text in the strip right of the plots, 140 px wide) with `getBBox`, and writes on
/// `<body>` how many it measured (`data-legend-texts`) and each pair whose boxes intersect, or a
/// label outside its figure (`data-legend-overlaps`, `none` when there is none).
const LEGEND_CHECK: &str = r#"<script>
(function () {
  var measured = 0, overlaps = [];
  document.querySelectorAll('figure.plot').forEach(function (figure) {
    var id = figure.getAttribute('data-figure') || '';
    if (!/-(errors|wheels|trajectory)$/.test(id)) { return; }
    var svg = figure.querySelector('svg');
    var width = parseFloat(svg.getAttribute('width'));
    var height = parseFloat(svg.getAttribute('height'));
    var boxes = [];
    svg.querySelectorAll('text').forEach(function (text) {
      if (parseFloat(text.getAttribute('x')) < width - 140) { return; }
      var b = text.getBBox();
      boxes.push({ label: text.textContent.trim(), x0: b.x, y0: b.y, x1: b.x + b.width, y1: b.y + b.height });
    });
    measured += boxes.length;
    boxes.forEach(function (a, i) {
      if (a.x0 < 0 || a.y0 < 0 || a.x1 > width || a.y1 > height) {
        overlaps.push(id + ': ' + a.label + ' leaves the figure');
      }
      boxes.slice(i + 1).forEach(function (b) {
        // Boxes that intersect by more than half a pixel each way.
        if (Math.min(a.x1, b.x1) - Math.max(a.x0, b.x0) > 0.5 &&
            Math.min(a.y1, b.y1) - Math.max(a.y0, b.y0) > 0.5) {
          overlaps.push(id + ': ' + a.label + ' / ' + b.label);
        }
      });
    });
  });
  document.body.setAttribute('data-legend-texts', String(measured));
  document.body.setAttribute('data-legend-overlaps', overlaps.length ? overlaps.join(' | ') : 'none');
})();
</script>"#;

/// Issue 39: with 16 robots the legends of "robot 14–16" and "v* = 0.7 m/s" were drawn on one
/// line. In Chromium, no two legend labels of a 16- or 32-robot run's figures intersect, and
/// none leaves its figure; the same check finds the overlap of a legend drawn one row too close.
#[test]
fn in_chromium_the_legends_of_16_and_32_robots_do_not_overlap() {
    let browser = chromium();
    let (dir, out, summary) = report_of(|data| {
        common::write_team_dir(&data.join("sixteen"), 16, 20.0);
        common::write_team_dir(&data.join("thirty-two"), 32, 20.0);
    });
    assert_eq!(summary.runs_drawn, 2);
    let html = std::fs::read_to_string(&out).expect("html");
    // The page with the legend check added, in Chromium with a fresh profile.
    let check_legends = |page: &str, profile: &str| {
        let checked = page.replace("</body>", &format!("{LEGEND_CHECK}</body>"));
        dump_written_page(&browser, dir.path(), "checked.html", &checked, profile)
    };
    let run = check_legends(&html, "profile-legends");
    let measured: usize = body_attribute(&run.stdout, "data-legend-texts")
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("the legend check did not run\nstderr:\n{}", run.stderr));
    // Per run: errors (2 edge rows, 2 tolerances; heading, 10 colours, zero), wheels (twice
    // heading, 10 colours, v*) and trajectory (heading, 10 colours, formation).
    assert!(
        measured >= 2 * (4 + 12 + 2 * 12 + 12),
        "{measured} legend labels"
    );
    assert_eq!(
        body_attribute(&run.stdout, "data-legend-overlaps").as_deref(),
        Some("none"),
        "overlapping legend labels"
    );

    // The check can fail: a legend label drawn twice on one line is found.
    let wheels = html.find("-wheels\"").expect("a wheel figure");
    let label = wheels + html[wheels..].find("v* = ").expect("the v* label");
    let start = html[..label].rfind("<text").expect("its text element");
    let end = label + html[label..].find("</text>").expect("its end") + "</text>".len();
    let doubled = format!("{}{}", &html[..end], &html[start..]);
    let run = check_legends(&doubled, "profile-doubled");
    let overlaps = body_attribute(&run.stdout, "data-legend-overlaps").unwrap_or_default();
    assert!(
        overlaps.contains("-wheels: v* = 0.4 m/s / v* = 0.4 m/s"),
        "{overlaps}"
    );
}
