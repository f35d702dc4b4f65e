//! The library's layering, read from the source: which top-level module uses which (through
//! `crate::…` paths outside test code). Data flows one way (STYLE.md): the module graph has no
//! cycle, no stage imports the editing session, and the front ends (the CLI, the GUI) run no
//! stage sequence of their own: they call the pipeline.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.flatten().map(|e| e.path()).collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The text of a file without its `#[cfg(test)]` items (a `mod … { … }` block or a one-line
/// `mod …;`) and without comments.
fn non_test_code(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let mut kept = String::new();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim();
        if line == "#[cfg(test)]" {
            let item = lines.get(i + 1).map(|l| l.trim()).unwrap_or("");
            i += 1;
            if item.ends_with('{') {
                let mut depth = 0i32;
                while i < lines.len() {
                    depth += lines[i].matches('{').count() as i32;
                    depth -= lines[i].matches('}').count() as i32;
                    i += 1;
                    if depth <= 0 {
                        break;
                    }
                }
            } else {
                i += 1;
            }
            continue;
        }
        let code = match lines[i].find("//") {
            Some(at) => &lines[i][..at],
            None => lines[i],
        };
        kept.push_str(code);
        kept.push('\n');
        i += 1;
    }
    kept
}

/// Top-level module names used through `prefix::name` or `prefix::{name, …}` in `code`.
fn used_modules(code: &str, prefix: &str, modules: &BTreeSet<String>) -> BTreeSet<String> {
    let mut used = BTreeSet::new();
    let pattern = format!("{prefix}::");
    let mut rest = code;
    while let Some(at) = rest.find(&pattern) {
        let before = rest[..at].chars().last();
        rest = &rest[at + pattern.len()..];
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
            continue;
        }
        let names: Vec<&str> = if let Some(group) = rest.strip_prefix('{') {
            let end = group.find('}').unwrap_or(group.len());
            group[..end]
                .split(',')
                .map(|item| item.trim().split("::").next().unwrap_or(""))
                .collect()
        } else {
            vec![
                rest.split(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .next()
                    .unwrap_or(""),
            ]
        };
        for name in names {
            if modules.contains(name) {
                used.insert(name.to_owned());
            }
        }
    }
    used
}

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Top-level library modules: `src/NAME/` folders and `src/NAME.rs` files.
fn modules() -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for entry in std::fs::read_dir(root().join("src")).unwrap().flatten() {
        let path = entry.path();
        let name = path.file_stem().unwrap().to_string_lossy().into_owned();
        if name == "lib" || name == "bin" || name == "main" {
            continue;
        }
        if path.is_dir() || path.extension().is_some_and(|e| e == "rs") {
            names.insert(name);
        }
    }
    names
}

/// Which modules each module uses (outside its tests).
fn module_graph() -> BTreeMap<String, BTreeSet<String>> {
    let modules = modules();
    let mut graph = BTreeMap::new();
    for module in &modules {
        let mut files = Vec::new();
        let folder = root().join("src").join(module);
        if folder.is_dir() {
            rust_files(&folder, &mut files);
        } else {
            files.push(root().join("src").join(format!("{module}.rs")));
        }
        let mut used = BTreeSet::new();
        for file in files {
            let code = non_test_code(&std::fs::read_to_string(&file).unwrap());
            used.extend(used_modules(&code, "crate", &modules));
        }
        used.remove(module);
        graph.insert(module.clone(), used);
    }
    graph
}

/// A cycle through `start`, if any (depth-first).
fn cycle_from(
    graph: &BTreeMap<String, BTreeSet<String>>,
    node: &str,
    path: &mut Vec<String>,
    done: &mut BTreeSet<String>,
) -> Option<Vec<String>> {
    if let Some(at) = path.iter().position(|n| n == node) {
        let mut cycle = path[at..].to_vec();
        cycle.push(node.to_owned());
        return Some(cycle);
    }
    if done.contains(node) {
        return None;
    }
    path.push(node.to_owned());
    for next in graph.get(node).into_iter().flatten() {
        if let Some(cycle) = cycle_from(graph, next, path, done) {
            return Some(cycle);
        }
    }
    path.pop();
    done.insert(node.to_owned());
    None
}

#[test]
fn the_module_graph_has_no_cycle() {
    let graph = module_graph();
    let mut done = BTreeSet::new();
    for module in graph.keys() {
        let mut path = Vec::new();
        if let Some(cycle) = cycle_from(&graph, module, &mut path, &mut done) {
            panic!("module cycle: {}\n{graph:#?}", cycle.join(" -> "));
        }
    }
}

#[test]
fn no_stage_imports_the_editing_session() {
    let graph = module_graph();
    let users: Vec<&String> = graph
        .iter()
        .filter(|(_, used)| used.contains("edit"))
        .map(|(module, _)| module)
        .collect();
    assert!(users.is_empty(), "modules importing edit: {users:?}");
}

#[test]
fn the_checker_sees_imports_and_skips_tests() {
    let modules: BTreeSet<String> = ["edit", "leaf", "scene"].map(String::from).into();
    let code = "use crate::{leaf::fit, scene};\nfn f() { crate::edit::Session::new(); }\n\
                #[cfg(test)]\nmod tests {\n    use crate::edit::Session; // a test may\n}\n";
    let stripped = non_test_code(code);
    let used = used_modules(&stripped, "crate", &modules);
    assert_eq!(used, modules);
    let without_body = non_test_code("#[cfg(test)]\nmod tests {\n use crate::edit;\n}\n");
    assert!(used_modules(&without_body, "crate", &modules).is_empty());
}

/// Stage functions that only the pipeline sequences; a front end calling one runs a stage
/// sequence of its own.
const STAGE_CALLS: [&str; 8] = [
    "reconstruct_leaves",
    "attach_leaves",
    "assemble_plant",
    "automatic_plant_skeleton",
    "skeleton_records",
    "model_branches",
    "segmentation_ply",
    "write_workspace",
];

#[test]
fn front_ends_call_the_pipeline_not_its_stages() {
    let mut files = vec![root().join("src/bin/frond.rs")];
    rust_files(&root().join("ui/src"), &mut files);
    let mut offences = Vec::new();
    for file in &files {
        let code = non_test_code(&std::fs::read_to_string(file).unwrap());
        for call in STAGE_CALLS {
            if code.contains(call) {
                offences.push(format!("{}: {call}", file.display()));
            }
        }
    }
    assert!(offences.is_empty(), "{offences:#?}");
}
