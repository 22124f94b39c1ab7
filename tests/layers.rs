//! The layers of the crate's modules, written once in docs/layout.md (its ```layers-rust block,
//! one module per line, lowest layer first) and checked here: a module uses only modules of its
//! own entry or of entries listed above it, and no modules use each other in a circle (within an
//! entry either). A module belongs to the longest entry that names it or one of its ancestors
//! (`ros::node` holds `ros::node::server`); `main` is the binary (src/main.rs).
//!
//! What counts as a use: every path in a `use` item (groups expanded) and every `crate::`,
//! `super::` or `self::` path in the code, resolved to the deepest module it names. Paths of other
//! crates are not ours to order. No build: a small lexer over the text, well under a second.

mod rust_source;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use rust_source::{code_only, is_ident, rust_files};

/// One use of a module by another, and where it is written.
#[derive(Debug, Clone)]
struct Use {
    from: String,
    to: String,
    at: String,
    path: String,
}

/// The module a file is (`sim::line`, `ros::node`; the library root is ``, the binary `main`).
fn file_module(file: &str) -> String {
    let rel = file.trim_start_matches("src/").trim_end_matches(".rs");
    if rel == "lib" || rel == "main" {
        return if rel == "lib" { String::new() } else { "main".to_string() };
    }
    rel.trim_end_matches("/mod").replace('/', "::")
}

fn join(parent: &str, child: &str) -> String {
    if parent.is_empty() {
        child.to_string()
    } else {
        format!("{parent}::{child}")
    }
}

fn parent(module: &str) -> String {
    module.rsplit_once("::").map_or(String::new(), |(p, _)| p.to_string())
}

/// The code's tokens with their line numbers: identifiers, `::`, and single punctuation.
fn tokens(text: &str) -> Vec<(String, usize)> {
    let code = code_only(text);
    let mut found = Vec::new();
    for (n, line) in code.lines().enumerate() {
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if is_ident(Some(c)) {
                let word: String = chars[i..].iter().take_while(|&&c| is_ident(Some(c))).collect();
                i += word.chars().count();
                found.push((word, n + 1));
            } else if c == ':' && chars.get(i + 1) == Some(&':') {
                found.push(("::".to_string(), n + 1));
                i += 2;
            } else {
                if !c.is_whitespace() {
                    found.push((c.to_string(), n + 1));
                }
                i += 1;
            }
        }
    }
    found
}

/// The module each token is in (inline `mod name { ... }` blocks included), and the inline modules.
fn token_modules(file_module: &str, toks: &[(String, usize)]) -> (Vec<String>, Vec<String>) {
    let mut stack: Vec<(String, usize)> = vec![(file_module.to_string(), 0)];
    let (mut depth, mut pending) = (0usize, None::<String>);
    let (mut at, mut inline) = (Vec::new(), Vec::new());
    for (i, (tok, _)) in toks.iter().enumerate() {
        at.push(stack.last().unwrap().0.clone());
        match tok.as_str() {
            "mod" => pending = toks.get(i + 1).map(|(name, _)| name.clone()),
            "{" => {
                depth += 1;
                if let Some(name) = pending.take().filter(|_| i >= 2 && toks[i - 2].0 == "mod") {
                    let module = join(&stack.last().unwrap().0, &name);
                    inline.push(module.clone());
                    stack.push((module, depth));
                }
            }
            "}" => {
                if stack.len() > 1 && stack.last().unwrap().1 == depth {
                    stack.pop();
                }
                depth = depth.saturating_sub(1);
            }
            ";" => pending = None,
            _ => {}
        }
    }
    (at, inline)
}

/// The paths of the `use` item whose tree starts at `toks[i]`, and the index after it.
fn use_tree(toks: &[(String, usize)], mut i: usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) -> usize {
    let mut path = prefix;
    while i < toks.len() {
        let tok = toks[i].0.as_str();
        match tok {
            "::" => i += 1,
            "{" => {
                i += 1;
                while i < toks.len() && toks[i].0 != "}" {
                    i = use_tree(toks, i, path.clone(), out);
                    if toks.get(i).is_some_and(|(t, _)| t == ",") {
                        i += 1;
                    }
                }
                return i + 1;
            }
            "*" => {
                out.push(path);
                return i + 1;
            }
            "as" => i += 2,
            "," | "}" | ";" => {
                out.push(path);
                return i;
            }
            "self" if !path.is_empty() => i += 1, // `a::{self, B}` names `a`
            _ => {
                path.push(tok.to_string());
                i += 1;
            }
        }
    }
    out.push(path);
    i
}

/// The module a path names (its deepest module), seen from `from`; `None` for other crates.
fn resolve(path: &[String], from: &str, crate_root: &str, modules: &BTreeSet<String>) -> Option<String> {
    let mut segments = path.iter().map(String::as_str).peekable();
    let mut module = match *segments.peek()? {
        "crate" => crate_root.to_string(),
        "sorting_line" => String::new(),
        "self" => from.to_string(),
        "super" => from.to_string(),
        first if modules.contains(&join(from, first)) => from.to_string(),
        _ => return None,
    };
    if matches!(path[0].as_str(), "crate" | "sorting_line" | "self") {
        segments.next();
    }
    while segments.peek() == Some(&"super") {
        segments.next();
        module = parent(&module);
    }
    for segment in segments {
        let child = join(&module, segment);
        if !modules.contains(&child) {
            break;
        }
        module = child;
    }
    Some(module)
}

/// Every use of one module by another in `sources` (file name under src/, text).
fn uses(sources: &[(String, String)]) -> (Vec<Use>, BTreeSet<String>) {
    let mut modules: BTreeSet<String> = sources.iter().map(|(file, _)| file_module(file)).collect();
    let scanned: Vec<_> = sources
        .iter()
        .map(|(file, text)| {
            let toks = tokens(text);
            let (at, inline) = token_modules(&file_module(file), &toks);
            modules.extend(inline);
            (file, toks, at)
        })
        .collect();
    let mut found = Vec::new();
    for (file, toks, at) in &scanned {
        let crate_root = if file.as_str() == "src/main.rs" { "main" } else { "" };
        let mut i = 0;
        while i < toks.len() {
            let (tok, line) = (&toks[i].0, toks[i].1);
            let mut paths = Vec::new();
            let next = if tok == "use" {
                use_tree(toks, i + 1, Vec::new(), &mut paths)
            } else if ["crate", "super", "self", "sorting_line"].contains(&tok.as_str())
                && toks.get(i + 1).is_some_and(|(t, _)| t == "::")
            {
                let mut j = i;
                let mut path = Vec::new();
                while j < toks.len() && is_ident(toks[j].0.chars().next()) {
                    path.push(toks[j].0.clone());
                    j += if toks.get(j + 1).is_some_and(|(t, _)| t == "::") { 2 } else { 1 };
                    if toks[j - 1].0 != "::" {
                        break;
                    }
                }
                paths.push(path);
                j
            } else {
                i + 1
            };
            for path in paths {
                if let Some(to) = resolve(&path, &at[i], crate_root, &modules) {
                    if to != at[i] {
                        let (from, at, path) = (at[i].clone(), format!("{file}:{line}"), path.join("::"));
                        found.push(Use { from, to, at, path });
                    }
                }
            }
            i = next.max(i + 1);
        }
    }
    (found, modules)
}

/// The entries of docs/layout.md's ```layers-rust block, lowest layer first.
fn layer_block(layout: &str) -> Vec<String> {
    let start = layout.find("```layers-rust\n").expect("docs/layout.md has no ```layers-rust block");
    let body = &layout[start + "```layers-rust\n".len()..];
    let end = body.find("```").expect("the ```layers-rust block is not closed");
    body[..end].lines().map(str::trim).filter(|l| !l.is_empty() && !l.starts_with('#')).map(String::from).collect()
}

/// The entry (its index in the block) that holds `module`.
fn entry_of(module: &str, entries: &[String]) -> Option<usize> {
    (0..entries.len())
        .filter(|&k| module == entries[k] || module.starts_with(&format!("{}::", entries[k])))
        .max_by_key(|&k| entries[k].len())
}

/// Every way `sources` break the layers `entries`: unknown entries, modules in no entry, uses
/// that run back up the order, and circles.
fn violations(sources: &[(String, String)], entries: &[String]) -> Vec<String> {
    let (uses, modules) = uses(sources);
    let mut found: Vec<String> = entries
        .iter()
        .filter(|e| !modules.contains(*e))
        .map(|e| format!("the layer entry `{e}` names no module of src/"))
        .collect();
    let mut graph: BTreeMap<&str, BTreeMap<&str, &Use>> = BTreeMap::new();
    for u in &uses {
        let (Some(from), Some(to)) = (entry_of(&u.from, entries), entry_of(&u.to, entries)) else {
            let lost = if entry_of(&u.from, entries).is_none() { &u.from } else { &u.to };
            found.push(format!("{}: module `{lost}` is in no layer entry (`{}`)", u.at, u.path));
            continue;
        };
        if to > from {
            found.push(format!(
                "{}: `{}` runs back up the layers: `{}` (entry `{}`) uses `{}` (entry `{}`, listed below it)",
                u.at, u.path, u.from, entries[from], u.to, entries[to]
            ));
        }
        graph.entry(&u.from).or_default().entry(&u.to).or_insert(u);
    }
    found.extend(circles(&graph));
    found
}

/// Each circle among the modules (a strongly connected group of more than one), with the uses of a
/// shortest way round it.
fn circles(graph: &BTreeMap<&str, BTreeMap<&str, &Use>>) -> Vec<String> {
    let reach = |start: &str| {
        let (mut seen, mut todo) = (BTreeSet::new(), vec![start.to_string()]);
        while let Some(m) = todo.pop() {
            for next in graph.get(m.as_str()).into_iter().flat_map(|e| e.keys()) {
                if seen.insert(next.to_string()) {
                    todo.push(next.to_string());
                }
            }
        }
        seen
    };
    let mut done = BTreeSet::new();
    let mut found = Vec::new();
    for &module in graph.keys() {
        if done.contains(module) || !reach(module).contains(module) {
            continue;
        }
        let group: Vec<String> = reach(module).into_iter().filter(|m| reach(m).contains(module)).collect();
        done.extend(group.iter().cloned());
        let steps: Vec<String> = shortest_circle(graph, module)
            .iter()
            .map(|u| format!("{} -> {} ({}: `{}`)", u.from, u.to, u.at, u.path))
            .collect();
        found.push(format!("circle among {group:?}: {}", steps.join("; ")));
    }
    found
}

/// The uses of a shortest way from `start` round to itself (breadth first).
fn shortest_circle<'a>(graph: &BTreeMap<&str, BTreeMap<&str, &'a Use>>, start: &str) -> Vec<&'a Use> {
    let mut came_by: BTreeMap<String, &Use> = BTreeMap::new();
    let mut todo = std::collections::VecDeque::from([start.to_string()]);
    while let Some(m) = todo.pop_front() {
        for (&next, &u) in graph.get(m.as_str()).into_iter().flatten() {
            if !came_by.contains_key(next) {
                came_by.insert(next.to_string(), u);
                todo.push_back(next.to_string());
            }
        }
        if came_by.contains_key(start) {
            break;
        }
    }
    let mut steps = vec![came_by[start]];
    while steps.last().unwrap().from != start {
        steps.push(came_by[steps.last().unwrap().from.as_str()]);
    }
    steps.reverse();
    steps
}

fn crate_sources() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    files.sort();
    files
        .into_iter()
        .map(|p| (p.strip_prefix(root).unwrap().display().to_string(), std::fs::read_to_string(&p).unwrap()))
        .collect()
}

#[test]
fn the_crate_keeps_the_layers_of_docs_layout() {
    let layout = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/layout.md")).unwrap();
    let entries = layer_block(&layout);
    let sources = crate_sources();
    let (found, _) = uses(&sources);
    assert!(found.len() > 150, "found only {} uses of the crate's modules in src/", found.len());
    let broken = violations(&sources, &entries);
    assert!(broken.is_empty(), "the layers of docs/layout.md are broken:\n{}", broken.join("\n"));
}

fn synthetic(files: &[(&str, &str)]) -> Vec<(String, String)> {
    files.iter().map(|(f, t)| (f.to_string(), t.to_string())).collect()
}

/// The check itself: a use that runs back up the order and a circle (across entries, and within
/// one through `super::`, a group and an inline module) are found; comments, strings and other
/// crates' paths are not uses.
#[test]
fn the_layer_check_can_fail() {
    let sources = synthetic(&[
        ("src/lib.rs", "pub mod a;\npub mod b;\npub mod c;\n"),
        ("src/a.rs", "use crate::b::Thing;\n// use crate::c::Nothing;\nconst S: &str = \"crate::c::x\";\n"),
        ("src/b.rs", "use std::fmt;\nfn f() { crate::a::g() }\n"),
        ("src/c/mod.rs", "mod x;\nuse x::X;\n#[cfg(test)]\nmod tests {\n    use super::*;\n}\n"),
        ("src/c/x.rs", "use super::{y, Y};\npub struct X;\n"),
    ]);
    let entries: Vec<String> = ["a", "b", "c", "d"].map(String::from).to_vec();
    let broken = violations(&sources, &entries);
    let has = |start: &str| broken.iter().any(|b| b.starts_with(start));
    assert_eq!(broken.len(), 4, "{broken:#?}");
    assert!(has("the layer entry `d` names no module of src/"), "{broken:#?}");
    assert!(has("src/a.rs:1: `crate::b::Thing` runs back up the layers: `a` (entry `a`) uses `b`"), "{broken:#?}");
    assert!(has("circle among [\"a\", \"b\"]: a -> b (src/a.rs:1: `crate::b::Thing`); b -> a"), "{broken:#?}");
    assert!(has("circle among [\"c\", \"c::x\"]: c -> c::x (src/c/mod.rs:2: `x::X`)"), "{broken:#?}");
}
