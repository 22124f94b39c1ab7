//! Size limits of the Rust sources in src/: no function over 80 lines, no file over 700 lines, so
//! that every function fits on a screen and every module is one concept. Generated tables
//! (`GENERATED`) are exempt. A function counts from its `fn` line to its closing brace, as rustfmt
//! lays it out (rustfmt.toml); its doc comment and attributes do not count. No build, no DDS: a
//! small lexer over the text, well under a second.

mod rust_source;

use rust_source::{code_only, is_ident, rust_files};
use std::path::Path;

const MAX_FUNCTION_LINES: usize = 80;
const MAX_FILE_LINES: usize = 700;
/// Files written by a generator, not by hand.
const GENERATED: [&str; 1] = ["src/ros/type_hash_table.rs"];

fn sources() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    files.sort();
    assert!(files.len() > 20, "found only {} Rust files under src/", files.len());
    files
        .into_iter()
        .map(|p| (p.strip_prefix(root).unwrap().display().to_string(), std::fs::read_to_string(&p).unwrap()))
        .filter(|(name, _)| !GENERATED.contains(&name.as_str()))
        .collect()
}

/// Every function with a body in `text`: (name, first line number, lines from `fn` to `}`).
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let code = code_only(text);
    let lines: Vec<&str> = code.lines().collect();
    let mut found = Vec::new();
    for (n, line) in lines.iter().enumerate() {
        let words: Vec<&str> = line.split(|c: char| !is_ident(Some(c))).filter(|w| !w.is_empty()).collect();
        let Some(at) = words.iter().position(|w| *w == "fn") else { continue };
        let Some(name) = words.get(at + 1) else { continue };
        // The body: the first `{` at depth 0 of brackets after the name, unless a `;` comes first.
        let (mut depth, mut brackets) = (0i64, 0i64);
        let mut opened = false;
        'scan: for (m, l) in lines.iter().enumerate().skip(n) {
            let start = if m == n { line.find(&format!("fn {name}")).unwrap_or(0) } else { 0 };
            for c in l[start..].chars() {
                match c {
                    '(' | '[' => brackets += 1,
                    ')' | ']' => brackets -= 1,
                    ';' if !opened && brackets == 0 => break 'scan,
                    '{' if opened || brackets == 0 => {
                        opened = true;
                        depth += 1;
                    }
                    '}' if opened => {
                        depth -= 1;
                        if depth == 0 {
                            found.push((name.to_string(), n + 1, m - n + 1));
                            break 'scan;
                        }
                    }
                    _ => {}
                }
            }
        }
    }
    found
}

#[test]
fn no_rust_file_in_src_is_over_700_lines() {
    let long: Vec<String> = sources()
        .iter()
        .map(|(name, text)| (name, text.lines().count()))
        .filter(|&(_, n)| n > MAX_FILE_LINES)
        .map(|(name, n)| format!("{name} ({n} lines)"))
        .collect();
    assert!(long.is_empty(), "files over {MAX_FILE_LINES} lines (split them by concept): {long:?}");
}

#[test]
fn no_rust_function_in_src_is_over_80_lines() {
    let mut long = Vec::new();
    let mut counted = 0;
    for (file, text) in sources() {
        for (name, line, n) in functions(&text) {
            counted += 1;
            if n > MAX_FUNCTION_LINES {
                long.push(format!("{file}:{line} {name} ({n} lines)"));
            }
        }
    }
    assert!(counted > 300, "found only {counted} functions in src/");
    assert!(long.is_empty(), "functions over {MAX_FUNCTION_LINES} lines (split them): {long:?}");
}

/// The measure itself: braces in strings, chars and comments do not count, a declaration without
/// a body is no function, and an 81-line function is over the limit.
#[test]
fn the_size_checks_can_fail() {
    let body: String = (0..79).map(|k| format!("    let x{k} = \"{{\"; // }}\n")).collect();
    let text = format!(
        "trait T {{\n    fn f(&self);\n}}\nfn long() {{\n{body}}}\nfn short(c: char) -> bool {{\n    c == '{{'\n}}\n"
    );
    assert_eq!(functions(&text), vec![("long".to_string(), 4, 81), ("short".to_string(), 85, 3)], "{text}");
}
