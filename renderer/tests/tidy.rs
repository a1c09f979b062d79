//! The renderer's size rules, checked on its own source: no file in `renderer/src` over 600
//! lines, no function over 100 (issue 27's targets: a file does one job, a function reads on
//! one screen or two). In the spirit of rust-analyzer's `tidy` tests: a rule that only lives in
//! a review is broken by the next change that nobody reviews for it.

use std::path::{Path, PathBuf};

const MAX_FILE_LINES: usize = 600;
const MAX_FN_LINES: usize = 100;

/// Every `.rs` file under `dir`, sorted.
fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(d) = pending.pop() {
        for entry in std::fs::read_dir(&d).expect("source folder") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                pending.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// `line` with its comment, string and character literals blanked, so that only code braces
/// remain (strings that span lines are rare here and carry no braces; a lifetime's quote is
/// kept as it is).
fn code_of(line: &str) -> String {
    let chars: Vec<char> = line.chars().collect();
    let mut out = String::new();
    let mut i = 0;
    while i < chars.len() {
        match chars[i] {
            '/' if chars.get(i + 1) == Some(&'/') => break,
            '"' => {
                i += 1;
                while i < chars.len() && chars[i] != '"' {
                    i += if chars[i] == '\\' { 2 } else { 1 };
                }
                out.push_str("\"\"");
            }
            '\'' if chars.get(i + 1) == Some(&'\\') => {
                i += 2;
                while i < chars.len() && chars[i] != '\'' {
                    i += 1;
                }
                out.push_str("' '");
            }
            '\'' if chars.get(i + 2) == Some(&'\'') => {
                i += 2;
                out.push_str("' '");
            }
            c => out.push(c),
        }
        i += 1;
    }
    out
}

/// The name of the function `line` declares, if it declares one.
fn declared_fn(line: &str) -> Option<&str> {
    let mut rest = line.trim_start();
    for prefix in [
        "pub(crate) ",
        "pub(super) ",
        "pub ",
        "const ",
        "async ",
        "unsafe ",
        "extern \"C\" ",
    ] {
        rest = rest.strip_prefix(prefix).unwrap_or(rest);
    }
    let name = rest.strip_prefix("fn ")?;
    let end = name
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(name.len());
    Some(&name[..end])
}

/// Every function of `text` with a body, as (name, first line, lines from its signature to
/// its closing brace).
fn functions(text: &str) -> Vec<(String, usize, usize)> {
    let lines: Vec<String> = text.lines().map(code_of).collect();
    let mut found = Vec::new();
    for (start, line) in lines.iter().enumerate() {
        let Some(name) = declared_fn(line) else {
            continue;
        };
        let mut depth = 0i64;
        let mut opened = false;
        for (k, l) in lines.iter().enumerate().skip(start) {
            for c in l.chars() {
                match c {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    _ => {}
                }
            }
            if opened && depth <= 0 {
                found.push((name.to_string(), start + 1, k - start + 1));
                break;
            }
            if !opened && l.trim_end().ends_with(';') {
                break; // a declaration without a body (a trait's)
            }
        }
    }
    found
}

#[test]
fn files_and_functions_stay_within_their_sizes() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = sources(&src);
    assert!(files.len() > 40, "found only {} sources", files.len());
    let mut too_long = Vec::new();
    let mut counted = 0;
    for path in &files {
        let text = std::fs::read_to_string(path).expect("source");
        let name = path.strip_prefix(&src).unwrap_or(path).display();
        let n = text.lines().count();
        if n > MAX_FILE_LINES {
            too_long.push(format!("{name}: {n} lines (at most {MAX_FILE_LINES})"));
        }
        for (f, at, n) in functions(&text) {
            counted += 1;
            if n > MAX_FN_LINES {
                too_long.push(format!(
                    "{name}:{at}: fn {f} is {n} lines (at most {MAX_FN_LINES})"
                ));
            }
        }
    }
    assert!(counted > 300, "found only {counted} functions");
    assert!(too_long.is_empty(), "{too_long:#?}");
}

/// The control: the counter sees a long function as long, through braces in strings,
/// characters and comments, and skips bodiless declarations.
#[test]
fn the_counter_measures_what_it_should() {
    let mut text = String::from("trait T {\n    fn declared(&self);\n}\n");
    text.push_str("pub(crate) fn long() -> char {\n    let s = \"{{ \\\" {\"; // }}}\n");
    for _ in 0..97 {
        text.push_str("    let _ = 1;\n");
    }
    text.push_str("    '{'\n}\nfn short<'a>(x: &'a str) -> &'a str {\n    x\n}\n");
    let found = functions(&text);
    assert_eq!(
        found,
        vec![("long".to_string(), 4, 101), ("short".to_string(), 105, 3),]
    );
}
