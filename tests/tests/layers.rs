//! The workspace's layering, checked against what ARCHITECTURE.md promises, so it cannot drift.
//!
//! * **What each crate builds.** A crate's "must not" cell in ARCHITECTURE.md's crate table may
//!   say "build `a`, `b` or `c`": then `cargo tree -e normal -p <crate>` (the crate built on its
//!   own, with its default features) lists none of those crates.
//! * **One name per crate.** Every workspace package lives in the folder `<name>/` and is called
//!   `formation-<name>`, and its library is `formation_<name>` (an example's, in
//!   `examples/<name>/`, `formation-example-<name>`).
//! * **One package per process.** `formation`, `formation-world` and `formation-agent` are each
//!   the only binary of a package of their own; the agent's demo build holds none of tokio,
//!   plotters or rayon, and with Zenoh on, tokio only under Zenoh.
//! * **No module cycle.** Within each crate, the top-level modules' `crate::` (and `super::`)
//!   references form no cycle.
//!
//! They run cargo itself (`cargo tree`, `cargo metadata`), offline against the lock file, and read
//! the sources.

use std::collections::{BTreeMap, BTreeSet};
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
    normal_dependencies_with(package, &[])
}

/// What `cargo tree -e normal -p <package> <flags>` prints (locked and offline).
fn normal_tree(package: &str, flags: &[&str]) -> String {
    let mut args = vec![
        "tree",
        "--locked",
        "--offline",
        "-e",
        "normal",
        "-p",
        package,
    ];
    args.extend_from_slice(flags);
    cargo(&args)
}

/// The crate names `cargo tree -e normal -p <package> <flags>` lists.
fn normal_dependencies_with(package: &str, flags: &[&str]) -> BTreeSet<String> {
    let mut flags = flags.to_vec();
    flags.extend_from_slice(&["--prefix", "none", "--format", "{p}"]);
    normal_tree(package, &flags)
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
        "formation-agent-node",
        "formation-runtime",
        "formation-transport-iceoryx2",
        "formation-transport-zenoh",
        "formation-transport-ros2",
        "formation-example-transport-unix-datagram",
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
fn with_every_feature_the_runtime_builds_no_transport() {
    let built = normal_dependencies_with("formation-runtime", &["--all-features"]);
    assert!(built.contains("formation-runtime"), "{built:?}");
    for transport in ["iceoryx2", "zenoh", "formation-ros2"] {
        assert!(
            !built.contains(transport),
            "formation-runtime builds {transport} (see `cargo tree -e normal --all-features -i \
             {transport} -p formation-runtime`)"
        );
    }
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
    let metadata = workspace_metadata();
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
        // An example crate in `examples/<name>/` is `formation-example-<name>`.
        let expected = match folder.strip_prefix("examples/") {
            Some(example) => format!("formation-example-{example}"),
            None => format!("formation-{folder}"),
        };
        if name != expected {
            wrong.push(format!(
                "folder {folder}/ holds package {name}, not {expected}"
            ));
        }
        for lib_name in targets_of(package, "lib") {
            if lib_name != expected.replace('-', "_") {
                wrong.push(format!("package {name} has the library {lib_name}"));
            }
        }
    }
    assert!(wrong.is_empty(), "one name per crate: {wrong:?}");
}

/// `cargo metadata --no-deps` of the workspace.
fn workspace_metadata() -> serde_json::Value {
    serde_json::from_str(&cargo(&["metadata", "--no-deps", "--format-version", "1"]))
        .expect("cargo metadata prints JSON")
}

/// The names of a package's targets of `kind` (`bin`, `lib`).
fn targets_of(package: &serde_json::Value, kind: &str) -> Vec<String> {
    package["targets"]
        .as_array()
        .expect("targets")
        .iter()
        .filter(|t| {
            t["kind"]
                .as_array()
                .is_some_and(|k| k.iter().any(|k| k == kind))
        })
        .filter_map(|t| t["name"].as_str().map(str::to_owned))
        .collect()
}

#[test]
fn each_process_is_the_only_binary_of_its_own_package() {
    let metadata = workspace_metadata();
    let packages = metadata["packages"].as_array().expect("packages");
    for (binary, package) in [
        ("formation", "formation-cli"),
        ("formation-world", "formation-world-node"),
        ("formation-agent", "formation-agent-node"),
    ] {
        let owners: Vec<&str> = packages
            .iter()
            .filter(|p| targets_of(p, "bin").iter().any(|b| b == binary))
            .filter_map(|p| p["name"].as_str())
            .collect();
        assert_eq!(owners, [package], "the binary {binary} is in {owners:?}");
        let owner = packages
            .iter()
            .find(|p| p["name"] == package)
            .expect("the package");
        assert_eq!(
            targets_of(owner, "bin"),
            [binary],
            "{package} holds other binaries beside {binary}"
        );
    }
    // `cargo build` (the workspace's default members) builds all three.
    let members: BTreeSet<String> = metadata["workspace_default_members"]
        .as_array()
        .expect("default members")
        .iter()
        .filter_map(|id| packages.iter().find(|p| p["id"] == *id))
        .filter_map(|p| p["name"].as_str().map(str::to_owned))
        .collect();
    for package in [
        "formation-cli",
        "formation-world-node",
        "formation-agent-node",
    ] {
        assert!(
            members.contains(package),
            "{package} is not a default member: {members:?}"
        );
    }
}

#[test]
fn the_agents_demo_build_holds_no_tokio_plotters_or_rayon() {
    let built = normal_dependencies("formation-agent-node");
    assert!(built.contains("formation-agent-node"), "{built:?}");
    for heavy in ["tokio", "plotters", "rayon"] {
        assert!(
            !built.contains(heavy),
            "formation-agent-node builds {heavy} (see `cargo tree -e normal -p \
             formation-agent-node -i {heavy}`)"
        );
    }
}

#[test]
fn with_zenoh_the_agent_builds_tokio_only_under_zenoh() {
    let tree = normal_tree(
        "formation-agent-node",
        &[
            "--features",
            "zenoh",
            "--no-dedupe",
            "--prefix",
            "depth",
            "--format",
            "{p}",
        ],
    );
    let mut path: Vec<String> = Vec::new();
    let mut found = 0;
    for line in tree.lines() {
        let digits = line.chars().take_while(char::is_ascii_digit).count();
        let Ok(depth) = line[..digits].parse::<usize>() else {
            continue;
        };
        let name = line[digits..]
            .split_whitespace()
            .next()
            .unwrap_or_default()
            .to_owned();
        path.truncate(depth);
        if name == "tokio" {
            found += 1;
            assert!(
                path.iter().any(|p| p.starts_with("zenoh")),
                "tokio reached outside zenoh: {}",
                path.join(" -> ")
            );
        }
        path.push(name);
    }
    assert!(
        found > 0,
        "with Zenoh the agent builds tokio (through zenoh); the tree has none"
    );
}

/// Rust source without comment lines and without its trailing `#[cfg(test)] mod tests`.
fn code_of(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(at) => &text[..at],
        None => &text[..],
    };
    text.lines()
        .filter(|line| !line.trim_start().starts_with("//"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The identifiers named at each `prefix` (`crate::a`, `crate::{a, b::{c, d}}`): `a`, then `a`
/// and `b`.
fn names_after(code: &str, prefix: &str) -> Vec<String> {
    let ident = |s: &str| -> String {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect()
    };
    let mut names = Vec::new();
    for (at, _) in code.match_indices(prefix) {
        let rest = &code[at + prefix.len()..];
        let Some(group) = rest.strip_prefix('{') else {
            names.push(ident(rest));
            continue;
        };
        // The group's items at its top level: split at commas outside nested braces.
        let (mut depth, mut start) = (0usize, 0usize);
        for (i, c) in group.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    names.push(ident(&group[start..i]));
                    break;
                }
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    names.push(ident(&group[start..i]));
                    start = i + 1;
                }
                _ => {}
            }
        }
    }
    names.retain(|n| !n.is_empty());
    names
}

/// Every `.rs` file at or under `path`.
fn rust_files(path: &Path) -> Vec<PathBuf> {
    if path.is_file() {
        return vec![path.to_path_buf()];
    }
    let mut files = Vec::new();
    for entry in std::fs::read_dir(path).into_iter().flatten().flatten() {
        let entry = entry.path();
        if entry.is_dir() {
            files.extend(rust_files(&entry));
        } else if entry.extension().is_some_and(|e| e == "rs") {
            files.push(entry);
        }
    }
    files
}

/// The crate in `src` as a graph of its top-level modules: which modules each one's code names
/// through `crate::` (a name the crate root re-exports counts as its module), or through
/// `super::` from a module's own file.
fn module_graph(src: &Path, root: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut modules: BTreeMap<String, PathBuf> = BTreeMap::new();
    for entry in std::fs::read_dir(src).expect("src folder").flatten() {
        let path = entry.path();
        let stem = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default();
        let is_module_file =
            path.extension().is_some_and(|e| e == "rs") && !matches!(stem, "lib" | "main");
        if (is_module_file || path.is_dir()) && stem != "bin" {
            modules.insert(stem.to_owned(), path);
        }
    }
    let root_code = code_of(root);
    let mut reexported: BTreeMap<String, String> = BTreeMap::new();
    for (at, _) in root_code.match_indices("pub use ") {
        let rest = &root_code[at + "pub use ".len()..];
        let Some((module, items)) = rest.split_once("::") else {
            continue;
        };
        for item in names_after(&format!("x::{items}"), "x::") {
            reexported.insert(item, module.to_owned());
        }
    }
    let mut graph = BTreeMap::new();
    for (module, path) in &modules {
        let mut named = BTreeSet::new();
        for file in rust_files(path) {
            let code = code_of(&file);
            let mut names = names_after(&code, "crate::");
            if file == *path {
                names.extend(names_after(&code, "super::"));
            }
            for name in names {
                let name = reexported.get(&name).cloned().unwrap_or(name);
                if name != *module && modules.contains_key(&name) {
                    named.insert(name);
                }
            }
        }
        graph.insert(module.clone(), named);
    }
    graph
}

/// The graph's cycles: its strongly connected components of more than one module, each sorted.
fn cycles(graph: &BTreeMap<String, BTreeSet<String>>) -> BTreeSet<Vec<String>> {
    let reaches = |from: &str| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut stack = vec![from.to_owned()];
        while let Some(module) = stack.pop() {
            for next in graph.get(&module).into_iter().flatten() {
                if seen.insert(next.clone()) {
                    stack.push(next.clone());
                }
            }
        }
        seen
    };
    let reach: BTreeMap<&String, BTreeSet<String>> =
        graph.keys().map(|m| (m, reaches(m))).collect();
    graph
        .keys()
        .filter(|m| reach[m].contains(*m))
        .map(|m| {
            graph
                .keys()
                .filter(|other| reach[m].contains(*other) && reach[other].contains(m))
                .cloned()
                .collect()
        })
        .collect()
}

#[test]
fn a_module_cycle_is_found_and_a_layered_crate_has_none() {
    let graph = |edges: &[(&str, &[&str])]| -> BTreeMap<String, BTreeSet<String>> {
        edges
            .iter()
            .map(|(m, to)| (m.to_string(), to.iter().map(|t| t.to_string()).collect()))
            .collect()
    };
    let layered = graph(&[("read", &["error"]), ("write", &["error"]), ("error", &[])]);
    assert!(cycles(&layered).is_empty());
    let tangled = graph(&[("a", &["b"]), ("b", &["c"]), ("c", &["a"]), ("d", &["a"])]);
    assert_eq!(
        cycles(&tangled),
        BTreeSet::from([vec!["a".to_owned(), "b".to_owned(), "c".to_owned()]])
    );
    assert_eq!(
        names_after(
            "use crate::{read::{A, B}, error};\nx(crate::file::f)",
            "crate::"
        ),
        ["read", "error", "file"]
    );
}

#[test]
fn no_crate_has_a_module_cycle() {
    let metadata = workspace_metadata();
    let mut found: BTreeSet<(String, Vec<String>)> = BTreeSet::new();
    let mut crates = 0;
    for package in metadata["packages"].as_array().expect("packages") {
        let folder = Path::new(package["manifest_path"].as_str().expect("manifest path"))
            .parent()
            .expect("package folder")
            .to_path_buf();
        let src = folder.join("src");
        let root = ["lib.rs", "main.rs"]
            .iter()
            .map(|r| src.join(r))
            .find(|r| r.is_file());
        let Some(root) = root else {
            continue;
        };
        crates += 1;
        let name = folder
            .file_name()
            .and_then(|n| n.to_str())
            .unwrap_or_default()
            .to_owned();
        for cycle in cycles(&module_graph(&src, &root)) {
            found.insert((name.clone(), cycle));
        }
    }
    assert!(crates >= 10, "only {crates} crates read");
    assert!(
        found.is_empty(),
        "module cycles (crate, modules that reach each other through `crate::`/`super::`): \
         {found:?}; break them (a module below both sides)"
    );
}

/// Issue 35's map a newcomer reads in ten minutes: ARCHITECTURE.md of at most 3,000 words whose
/// table cells are at most 300 characters, and a README of at most 40 lines in every crate.
#[test]
fn the_map_is_short_and_every_crate_has_a_short_readme() {
    let root = repo_root().canonicalize().unwrap();
    let architecture =
        std::fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let words = architecture.split_whitespace().count();
    assert!(
        words <= 3000,
        "ARCHITECTURE.md has {words} words, above 3,000"
    );
    let long_cells: Vec<String> = architecture
        .lines()
        .filter(|line| line.trim_start().starts_with('|'))
        .flat_map(|line| line.split('|').map(str::trim))
        .filter(|cell| cell.chars().count() > 300)
        .map(|cell| cell.chars().take(60).collect())
        .collect();
    assert!(
        long_cells.is_empty(),
        "table cells above 300 characters: {long_cells:?}"
    );
    let metadata = workspace_metadata();
    let mut wrong = Vec::new();
    for package in metadata["packages"].as_array().expect("packages") {
        let manifest = Path::new(package["manifest_path"].as_str().expect("manifest path"));
        let readme = manifest.with_file_name("README.md");
        match std::fs::read_to_string(&readme) {
            Ok(text) if text.lines().count() <= 40 => {}
            Ok(text) => wrong.push(format!(
                "{}: {} lines",
                readme.display(),
                text.lines().count()
            )),
            Err(e) => wrong.push(format!("{}: {e}", readme.display())),
        }
    }
    assert!(
        wrong.is_empty(),
        "each crate's README, at most 40 lines: {wrong:?}"
    );
}
