//! The workspace's layering, checked against what ARCHITECTURE.md promises, so it cannot drift.
//!
//! * **What each crate builds.** A crate's "must not" cell in ARCHITECTURE.md's crate table may
//!   say "build `a`, `b` or `c`": then `cargo tree -e normal -p <crate>` (the crate built on its
//!   own, with its default features) lists none of those crates.
//! * **One name per crate.** Every workspace package lives in the folder `<name>/` and is called
//!   `formation-<name>`, and its library is `formation_<name>`.
//!
//! Both run cargo itself (`cargo tree`, `cargo metadata`), offline against the lock file.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::Command;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the repository root")
        .to_path_buf()
}

fn cargo(args: &[&str]) -> String {
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let output = Command::new(cargo)
        .current_dir(repo_root())
        .args(args)
        .output()
        .expect("running cargo");
    assert!(
        output.status.success(),
        "cargo {} failed:\n{}",
        args.join(" "),
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8(output.stdout).expect("cargo prints UTF-8")
}

/// One row of ARCHITECTURE.md's crate table: the package and the crates it must not build.
#[derive(Debug)]
struct LayerRule {
    package: String,
    must_not_build: Vec<String>,
}

/// The rows of the crate table (`| crate (dir) | holds | must not |`) whose "must not" cell says
/// "build `x`, `y` or `z`".
fn layer_rules(architecture: &str) -> Vec<LayerRule> {
    let mut rules = Vec::new();
    let mut in_table = false;
    for line in architecture.lines() {
        if line.starts_with("| crate (dir) | holds | must not |") {
            in_table = true;
            continue;
        }
        if in_table && !line.starts_with('|') {
            break;
        }
        if !in_table || line.starts_with("|---") {
            continue;
        }
        let cells: Vec<&str> = line.trim_matches('|').split(" | ").collect();
        let (Some(first), Some(must_not)) = (cells.first(), cells.last()) else {
            continue;
        };
        let Some(package) = backticked(first).into_iter().next() else {
            continue;
        };
        let Some(at) = must_not.find("build `") else {
            continue;
        };
        let listed = &must_not[at + "build ".len()..];
        let end = listed.find(';').unwrap_or(listed.len());
        rules.push(LayerRule {
            package,
            must_not_build: backticked(&listed[..end]),
        });
    }
    rules
}

fn backticked(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_owned)
        .collect()
}

/// The crate names `cargo tree -e normal -p <package>` lists.
fn normal_dependencies(package: &str) -> BTreeSet<String> {
    cargo(&[
        "tree",
        "--locked",
        "--offline",
        "-e",
        "normal",
        "-p",
        package,
        "--prefix",
        "none",
        "--format",
        "{p}",
    ])
    .lines()
    .filter_map(|line| line.split_whitespace().next())
    .map(str::to_owned)
    .collect()
}

#[test]
fn the_architecture_states_layers_for_the_pure_crates() {
    let architecture = std::fs::read_to_string(repo_root().join("ARCHITECTURE.md")).unwrap();
    let rules = layer_rules(&architecture);
    let ruled: BTreeSet<&str> = rules.iter().map(|r| r.package.as_str()).collect();
    for package in [
        "formation-proto",
        "formation-schema",
        "formation-world",
        "formation-expert",
        "formation-perception",
        "formation-report",
        "formation-robot-agent",
        "formation-python",
    ] {
        assert!(
            ruled.contains(package),
            "ARCHITECTURE.md's crate table states no \"build `...`\" rule for {package}: {rules:?}"
        );
    }
    for rule in &rules {
        assert!(
            !rule.must_not_build.is_empty(),
            "{}: the rule names no crate",
            rule.package
        );
    }
}

#[test]
fn every_crate_builds_none_of_what_the_architecture_forbids_it() {
    let architecture = std::fs::read_to_string(repo_root().join("ARCHITECTURE.md")).unwrap();
    let rules = layer_rules(&architecture);
    assert!(!rules.is_empty(), "no layer rules found in ARCHITECTURE.md");
    let mut broken = Vec::new();
    for rule in &rules {
        let built = normal_dependencies(&rule.package);
        assert!(
            built.contains(&rule.package),
            "cargo tree -p {} does not list the package itself: {built:?}",
            rule.package
        );
        for forbidden in &rule.must_not_build {
            if built.contains(forbidden) {
                broken.push(format!("{} builds {forbidden}", rule.package));
            }
        }
    }
    assert!(
        broken.is_empty(),
        "layering broken (see `cargo tree -e normal -i <crate> -p <package>`): {broken:?}"
    );
}

#[test]
fn a_layer_rule_is_read_from_its_table_cell() {
    let table = "\
| crate (dir) | holds | must not |
|---|---|---|
| `formation-a` (`a/`) | things | know about b; build `zenoh`, `tokio` or `ort`; panic |
| `formation-b` (`b/`) | more | run anything |
";
    let rules = layer_rules(table);
    assert_eq!(rules.len(), 1, "{rules:?}");
    assert_eq!(rules[0].package, "formation-a");
    assert_eq!(rules[0].must_not_build, ["zenoh", "tokio", "ort"]);
}

#[test]
fn every_crate_has_one_name_for_its_folder_package_and_library() {
    let metadata: serde_json::Value =
        serde_json::from_str(&cargo(&["metadata", "--no-deps", "--format-version", "1"]))
            .expect("cargo metadata prints JSON");
    let root = repo_root().canonicalize().unwrap();
    let packages = metadata["packages"].as_array().expect("packages");
    assert!(packages.len() >= 10, "{} packages", packages.len());
    let mut wrong = Vec::new();
    for package in packages {
        let name = package["name"].as_str().expect("package name");
        let manifest = Path::new(package["manifest_path"].as_str().expect("manifest path"));
        let folder = manifest
            .parent()
            .and_then(|dir| dir.strip_prefix(&root).ok())
            .map(|dir| dir.display().to_string())
            .unwrap_or_default();
        let expected = format!("formation-{folder}");
        if name != expected {
            wrong.push(format!(
                "folder {folder}/ holds package {name}, not {expected}"
            ));
        }
        let libs = package["targets"]
            .as_array()
            .expect("targets")
            .iter()
            .filter(|t| {
                t["kind"]
                    .as_array()
                    .is_some_and(|k| k.iter().any(|k| k == "lib"))
            });
        for lib in libs {
            let lib_name = lib["name"].as_str().unwrap_or_default();
            if lib_name != expected.replace('-', "_") {
                wrong.push(format!("package {name} has the library {lib_name}"));
            }
        }
    }
    assert!(wrong.is_empty(), "one name per crate: {wrong:?}");
}
