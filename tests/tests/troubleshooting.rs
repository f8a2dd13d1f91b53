//! The guide's troubleshooting chapter (`docs/src/troubleshooting.md`) against the product: every
//! error it quotes is still what the product prints.
//!
//! The chapter quotes errors in two kinds of fenced block, and this test reads both:
//! - a ```` ```console ```` block shows how to provoke the error: its `$ ` lines run, in order, in
//!   a scratch folder where `scenarios/` and `onnx/` are the repository's and `formation` is the
//!   built binary, and the last must fail (not with a panic) printing every other line of the
//!   block. A `…` in a quoted line stands for any text (a path, a number).
//! - a ```` ```text ```` block quotes a message that needs what a test cannot set up (a build
//!   without a feature, a machine without root): the line before it, `<!-- quoted from: PATH -->`,
//!   names the source file that prints it, and every quoted line must be in that file.
//!
//! A block of any other kind holding an error would go unchecked, so the chapter may hold only
//! these two kinds besides ```` ```sh ```` fixes.

use std::process::Command;
use std::time::Duration;

use formation_tests::{ProcessTest, binaries, repo_root, run};

const LIMIT: Duration = Duration::from_secs(300);
const CHAPTER: &str = "docs/src/troubleshooting.md";

/// One quoted error: how to provoke it, or where it is printed from.
#[derive(Debug)]
struct Quote {
    /// The chapter's line where the block starts.
    line: usize,
    /// `$ ` lines of a console block; empty for a text block.
    commands: Vec<String>,
    /// The quoted output lines.
    expected: Vec<String>,
    /// A text block's source file.
    source: Option<String>,
}

fn quotes(chapter: &str) -> Vec<Quote> {
    let lines: Vec<&str> = chapter.lines().collect();
    let mut found = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let Some(kind) = lines[i].strip_prefix("```") else {
            i += 1;
            continue;
        };
        let start = i;
        let end = (i + 1..lines.len())
            .find(|&j| lines[j].starts_with("```"))
            .unwrap_or_else(|| panic!("{CHAPTER}:{}: a fenced block never closes", start + 1));
        let body = &lines[start + 1..end];
        let expected = |skip_commands: bool| {
            let is_command = |l: &str| skip_commands && l.starts_with("$ ");
            body.iter()
                .filter(|l| !l.trim().is_empty() && !is_command(l))
                .map(|l| l.trim().to_owned())
                .collect::<Vec<_>>()
        };
        match kind.trim() {
            "console" => found.push(Quote {
                line: start + 1,
                commands: body
                    .iter()
                    .filter_map(|l| l.strip_prefix("$ ").map(str::to_owned))
                    .collect(),
                expected: expected(true),
                source: None,
            }),
            "text" => {
                let marker = lines[..start]
                    .iter()
                    .rev()
                    .find(|l| !l.trim().is_empty())
                    .and_then(|l| l.trim().strip_prefix("<!-- quoted from: "))
                    .and_then(|l| l.strip_suffix(" -->"))
                    .unwrap_or_else(|| {
                        panic!(
                            "{CHAPTER}:{}: a text block needs `<!-- quoted from: PATH -->` on the \
                             line before it, naming the file that prints it",
                            start + 1
                        )
                    });
                found.push(Quote {
                    line: start + 1,
                    commands: Vec::new(),
                    expected: expected(false),
                    source: Some(marker.to_owned()),
                });
            }
            "sh" => {}
            other => panic!(
                "{CHAPTER}:{}: a ```{other} block: quote errors in console or text blocks, and \
                 fixes in sh blocks, so that this test checks every quoted error",
                start + 1
            ),
        }
        i = end + 1;
    }
    found
}

/// `text` with ANSI colour codes removed, Rust string continuations (`\` + newline + indent)
/// joined, and every run of whitespace made one space.
fn normalized(text: &str) -> String {
    let mut plain = String::with_capacity(text.len());
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for d in chars.by_ref() {
                if d.is_ascii_alphabetic() {
                    break;
                }
            }
        } else if c == '\\' && chars.peek() == Some(&'\n') {
            while chars.peek().is_some_and(|d| d.is_whitespace()) {
                chars.next();
            }
        } else {
            plain.push(c);
        }
    }
    plain.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// Whether `haystack` holds `line`'s pieces (split at `…`) in order.
fn holds(haystack: &str, line: &str) -> bool {
    let mut rest = haystack;
    for piece in normalized(line).split('…').map(str::trim) {
        match rest.find(piece) {
            Some(at) => rest = &rest[at + piece.len()..],
            None => return false,
        }
    }
    true
}

/// Runs a console block's commands in a scratch folder of `t`'s of their own and checks its last
/// one fails printing every quoted line.
fn provoke(t: &ProcessTest, quote: &Quote) {
    let dir = t.folder(&format!("line-{}", quote.line));
    for shared in ["scenarios", "onnx"] {
        std::os::unix::fs::symlink(repo_root().join(shared), dir.join(shared))
            .expect("linking the repository's folders into the scratch folder");
    }
    let bin_dir = binaries().cli.parent().expect("the binaries' folder");
    let path = std::env::join_paths(std::iter::once(bin_dir.to_path_buf()).chain(
        std::env::split_paths(&std::env::var_os("PATH").unwrap_or_default()),
    ))
    .expect("PATH");
    let script = format!("set -e\n{}\n", quote.commands.join("\n"));
    let mut command = Command::new("sh");
    command
        .arg("-c")
        .arg(&script)
        .current_dir(&dir)
        .env("PATH", path)
        .env("ORT_DISABLE_TELEMETRY", "1");
    let finished = run(command, LIMIT);
    let context = format!(
        "{CHAPTER}:{}:\n{script}\n{}",
        quote.line,
        finished.describe()
    );
    assert!(
        !finished.output.status.success(),
        "the chapter's commands succeeded: {context}"
    );
    assert_ne!(
        finished.output.status.code(),
        Some(101),
        "a panic: {context}"
    );
    let printed = normalized(&format!("{}\n{}", finished.stdout(), finished.stderr()));
    assert!(!printed.contains("panicked"), "a panic: {context}");
    for line in &quote.expected {
        assert!(
            holds(&printed, line),
            "the product no longer prints the chapter's line {line:?}: update the chapter or the \
             message. {context}"
        );
    }
}

/// Checks a text block's every line is in its source file.
fn quoted_from_source(quote: &Quote) {
    let source = quote
        .source
        .as_deref()
        .expect("a text block names its source");
    let mut text = String::new();
    for file in source.split(", ") {
        let path = repo_root().join(file);
        text += &std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("{CHAPTER}:{}: {}: {e}", quote.line, path.display()));
    }
    let text = normalized(&text);
    for line in &quote.expected {
        assert!(
            holds(&text, line),
            "{CHAPTER}:{}: {source} no longer holds the quoted line {line:?}",
            quote.line
        );
    }
}

#[test]
fn every_error_the_troubleshooting_chapter_quotes_is_what_the_product_prints() {
    let t = ProcessTest::start("troubleshooting", LIMIT * 4);
    let chapter = std::fs::read_to_string(repo_root().join(CHAPTER)).expect("the chapter");
    let quotes = quotes(&chapter);
    let provoked: Vec<&Quote> = quotes.iter().filter(|q| q.source.is_none()).collect();
    // The chapter's main errors are provoked for real; the test cannot pass on an empty chapter.
    assert!(
        provoked.len() >= 8,
        "only {} provoked errors",
        provoked.len()
    );
    for quote in &quotes {
        assert!(
            !quote.expected.is_empty(),
            "{CHAPTER}:{}: the block quotes no output",
            quote.line
        );
        if quote.source.is_some() {
            quoted_from_source(quote);
        } else {
            assert!(
                !quote.commands.is_empty(),
                "{CHAPTER}:{}: a console block without a `$ ` command",
                quote.line
            );
            provoke(&t, quote);
        }
    }
}

#[test]
fn a_quote_matches_only_its_pieces_in_order() {
    let printed = normalized("error: scenario  a.toml:\n  unknown field `x`\u{1b}[0m");
    assert!(holds(&printed, "error: scenario … unknown field `x`"));
    assert!(!holds(&printed, "unknown field `x` … error"));
    assert!(!holds(&printed, "unknown field `y`"));
    assert!(holds(
        &normalized("\"a long \\\n     message\""),
        "a long message"
    ));
    let parsed = quotes(
        "```console\n$ formation x\nerror: y\n```\n<!-- quoted from: a.rs -->\n```text\nz\n```\n",
    );
    assert_eq!(parsed.len(), 2);
    assert_eq!(parsed[0].commands, ["formation x"]);
    assert_eq!(parsed[0].expected, ["error: y"]);
    assert_eq!(parsed[1].source.as_deref(), Some("a.rs"));
}
