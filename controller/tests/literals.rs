//! The robust law keeps no bare numeric literal in its logic but 0, 1 and 2 (and their float forms):
//! every other number is a named constant, with its derivation or the measurement that chose it where
//! it is defined, or a parameter's default. This test scans the law's sources and fails on any other.
//!
//! What is scanned: `controller/src/robust/**/*.rs` and the stages the law is built on
//! ([`SCANNED`]). What is not logic and so not scanned: comments and doc comments, string and
//! character literals, `const` and `static` items (the named constants themselves), `impl Default`
//! blocks and serde `fn default_*()` functions (parameter defaults), `fn validate` bodies (parameter
//! ranges, which name their own bounds), `#[cfg(test)]` items and `tests.rs` files, and tuple-field
//! indices (`p.0`). A number is allowed if it equals 0, 1 or 2, whatever its spelling (`0`, `1.0`,
//! `2_u32`, `0e0`).

use std::fs;
use std::path::{Path, PathBuf};

/// The directories and files (relative to the controller crate) whose logic is scanned.
const SCANNED: &[&str] = &[
    "src/robust",
    "src/estimator",
    "src/predictor",
    "src/onset",
    "src/conditioning.rs",
];

/// A bare literal found: file, line, the literal's text and the line's text.
#[derive(Debug, Clone, PartialEq)]
struct Bare {
    file: String,
    line: usize,
    literal: String,
    context: String,
}

/// Replaces comments, strings and character literals with spaces (newlines kept, so line numbers
/// hold).
fn strip_comments_and_strings(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let mut i = 0;
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
        } else if c == 'r' && (next == Some('"') || next == Some('#')) && !ident_before(&b, i) {
            // A raw string r"..." or r#"..."#.
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            j += 1;
            loop {
                if j >= b.len() {
                    break;
                }
                if b[j] == '"' && (0..hashes).all(|h| b.get(j + 1 + h) == Some(&'#')) {
                    j += 1 + hashes;
                    break;
                }
                j += 1;
            }
            for &ch in &b[i..j.min(b.len())] {
                out.push(blank(ch));
            }
            i = j;
        } else if c == '"' {
            out.push(' ');
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < b.len() {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
            out.push(' ');
            i += 1;
        } else if c == '\'' {
            // A character literal ('a', '\n', '\u{..}') or a lifetime ('a): a literal closes with a
            // quote within a few characters.
            let close = if next == Some('\\') {
                (i + 2..(i + 12).min(b.len())).find(|&j| b[j] == '\'')
            } else if b.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match close {
                Some(j) => {
                    for _ in i..=j {
                        out.push(' ');
                    }
                    i = j + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

fn ident_before(b: &[char], i: usize) -> bool {
    i > 0 && (b[i - 1].is_alphanumeric() || b[i - 1] == '_')
}

/// The end (exclusive) of the item that starts at `start`: through its matching `}` if a `{` comes
/// before a `;` at depth 0, else through the `;`.
fn item_end(b: &[char], start: usize) -> usize {
    let mut depth = 0i32;
    let mut i = start;
    while i < b.len() {
        match b[i] {
            '{' | '(' | '[' => depth += 1,
            '}' | ')' | ']' => {
                depth -= 1;
                if depth == 0 && b[i] == '}' {
                    // A block item closes here unless it is `const X: T = S { .. };`, whose `;`
                    // follows.
                    let rest: String = b[i + 1..]
                        .iter()
                        .take_while(|c| c.is_whitespace())
                        .collect();
                    let after = b.get(i + 1 + rest.chars().count()).copied();
                    return if after == Some(';') {
                        i + 2 + rest.chars().count()
                    } else {
                        i + 1
                    };
                }
            }
            ';' if depth == 0 => return i + 1,
            _ => {}
        }
        i += 1;
    }
    b.len()
}

/// Blanks the items that are not logic: `const`/`static` items, `impl Default` blocks, serde
/// `fn default_*` functions, `fn validate` bodies, and `#[cfg(test)]` items.
fn strip_non_logic(code: &str) -> String {
    blank_items(code, code, false)
}

/// Blanks in `text` the items [`strip_non_logic`] blanks (`tests_only`: only the `#[cfg(test)]`
/// items), found in `code`: `text` with its comments and strings blanked, character for character.
fn blank_items(code: &str, text: &str, tests_only: bool) -> String {
    let b: Vec<char> = code.chars().collect();
    let t: Vec<char> = text.chars().collect();
    assert_eq!(b.len(), t.len());
    let mut keep = vec![true; b.len()];
    let s: String = b.iter().collect();
    // The byte offset of each character.
    let offs: Vec<usize> = b
        .iter()
        .scan(0, |o, c| {
            let at = *o;
            *o += c.len_utf8();
            Some(at)
        })
        .collect();
    let starts_at = |i: usize, word: &str| -> bool {
        s[offs[i]..].starts_with(word)
            && !ident_before(&b, i)
            && b.get(i + word.chars().count())
                .is_none_or(|c| !(c.is_alphanumeric() || *c == '_'))
    };
    let mut i = 0;
    while i < b.len() {
        let blank_from = if starts_at(i, "#[cfg(test)]") {
            Some(i)
        } else if tests_only {
            None
        } else if (starts_at(i, "const") || starts_at(i, "static"))
            && !s[offs[i]..].starts_with("const fn")
            || starts_at(i, "impl") && header(&b, i).contains("Default for")
        {
            Some(i)
        } else if starts_at(i, "fn") {
            let h = header(&b, i);
            let name = h[2..].trim_start();
            (name.starts_with("default_") || name.starts_with("validate(")).then_some(i)
        } else {
            None
        };
        match blank_from {
            Some(from) => {
                // `#[cfg(test)]` applies to the next item: skip the attribute and blank that item.
                let item = if starts_at(from, "#[cfg(test)]") {
                    from + "#[cfg(test)]".len()
                } else {
                    from
                };
                let end = item_end(&b, item);
                for k in keep.iter_mut().take(end).skip(from) {
                    *k = false;
                }
                i = end;
            }
            None => i += 1,
        }
    }
    t.iter()
        .zip(keep)
        .map(|(&c, k)| if k || c == '\n' { c } else { ' ' })
        .collect()
}

/// The text from `i` up to the first `{` or `;`.
fn header(b: &[char], i: usize) -> String {
    b[i..]
        .iter()
        .take_while(|&&c| c != '{' && c != ';')
        .collect()
}

/// The numeric literals of `code` (comments, strings and non-logic items already blanked) whose
/// value is not 0, 1 or 2: `(line, literal)`.
fn bare_literals(code: &str) -> Vec<(usize, String)> {
    let b: Vec<char> = code.chars().collect();
    let mut found = Vec::new();
    let mut line = 1;
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        if c == '\n' {
            line += 1;
            i += 1;
            continue;
        }
        let starts_number = c.is_ascii_digit()
            && !ident_before(&b, i)
            // A tuple field (`p.0`, `(a, b).1`) is an index, not a number.
            && !(i > 0 && b[i - 1] == '.' && !(i > 1 && b[i - 2] == '.'));
        if !starts_number {
            i += 1;
            continue;
        }
        let start = i;
        let digits = |i: &mut usize| {
            while *i < b.len() && (b[*i].is_ascii_alphanumeric() || b[*i] == '_') {
                // Digits, `_`, hex digits, and a suffix; an exponent is taken below.
                if (b[*i] == 'e' || b[*i] == 'E') && matches!(b.get(*i + 1), Some('+') | Some('-'))
                {
                    *i += 2;
                    continue;
                }
                *i += 1;
            }
        };
        digits(&mut i);
        // A fractional part: `.` followed by a digit (not `..`, not a method call `1.max(..)`).
        if b.get(i) == Some(&'.') && b.get(i + 1).is_some_and(|c| c.is_ascii_digit()) {
            i += 1;
            digits(&mut i);
        } else if b.get(i) == Some(&'.')
            && !b
                .get(i + 1)
                .is_some_and(|c| *c == '.' || c.is_alphabetic() || *c == '_')
        {
            i += 1; // `1.`
        }
        let text: String = b[start..i].iter().collect();
        if !allowed(&text) {
            found.push((line, text));
        }
    }
    found
}

/// Whether a literal's value is 0, 1 or 2.
fn allowed(text: &str) -> bool {
    let t: String = text.chars().filter(|&c| c != '_').collect();
    if t.starts_with("0x") || t.starts_with("0o") || t.starts_with("0b") {
        return false;
    }
    let t = [
        "f64", "f32", "u8", "u16", "u32", "u64", "usize", "i8", "i16", "i32", "i64", "isize",
    ]
    .iter()
    .find_map(|s| t.strip_suffix(s))
    .unwrap_or(&t);
    t.parse::<f64>()
        .is_ok_and(|v| v == 0.0 || v == 1.0 || v == 2.0)
}

/// The bare literals of one source file's text.
fn scan_source(file: &str, src: &str) -> Vec<Bare> {
    let code = strip_non_logic(&strip_comments_and_strings(src));
    let lines: Vec<&str> = src.lines().collect();
    bare_literals(&code)
        .into_iter()
        .map(|(line, literal)| Bare {
            file: file.to_string(),
            line,
            literal,
            context: lines.get(line - 1).unwrap_or(&"").trim().to_string(),
        })
        .collect()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    if dir.is_file() {
        out.push(dir.to_path_buf());
        return;
    }
    let mut entries: Vec<_> = fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|e| e == "rs")
            && p.file_name().is_some_and(|n| n != "tests.rs")
        {
            out.push(p);
        }
    }
}

#[test]
fn the_robust_law_keeps_no_bare_numeric_literal() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for s in SCANNED {
        rust_files(&root.join(s), &mut files);
    }
    assert!(files.len() > 10, "the scan found only {files:?}");
    let mut bare = Vec::new();
    for f in &files {
        let src = fs::read_to_string(f).unwrap();
        let name = f.strip_prefix(&root).unwrap().display().to_string();
        bare.extend(scan_source(&name, &src));
    }
    let listing: Vec<String> = bare
        .iter()
        .map(|b| format!("{}:{}: `{}` in `{}`", b.file, b.line, b.literal, b.context))
        .collect();
    assert!(
        bare.is_empty(),
        "{} bare numeric literal(s) in the robust law's logic: name each as a constant (with where it \
         comes from) or make it a parameter:\n{}",
        bare.len(),
        listing.join("\n")
    );
}

/// The `const` and `static` items of a source file that no doc comment (`///`) or comment (`//`)
/// precedes: `(line, text)`. A named constant says where it comes from.
fn undocumented_constants(src: &str) -> Vec<(usize, String)> {
    let outside_tests = blank_items(&strip_comments_and_strings(src), src, true);
    let lines: Vec<&str> = outside_tests.lines().collect();
    let mut found = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim_start();
        let t = t
            .strip_prefix("pub(crate) ")
            .or_else(|| t.strip_prefix("pub(super) "))
            .or_else(|| t.strip_prefix("pub "))
            .unwrap_or(t);
        if !(t.starts_with("const ") && !t.starts_with("const fn") || t.starts_with("static ")) {
            continue;
        }
        let mut j = i;
        while j > 0 && lines[j - 1].trim_start().starts_with("#[") {
            j -= 1;
        }
        let documented = j > 0 && lines[j - 1].trim_start().starts_with("//");
        if !documented {
            found.push((i + 1, l.trim().to_string()));
        }
    }
    found
}

#[test]
fn every_named_constant_of_the_robust_law_is_documented() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for s in SCANNED {
        rust_files(&root.join(s), &mut files);
    }
    let mut missing = Vec::new();
    for f in &files {
        let src = fs::read_to_string(f).unwrap();
        let name = f.strip_prefix(&root).unwrap().display();
        for (line, text) in undocumented_constants(&src) {
            missing.push(format!("{name}:{line}: `{text}`"));
        }
    }
    assert!(
        missing.is_empty(),
        "constants without a comment saying where they come from:\n{}",
        missing.join("\n")
    );
}

// The scanner itself: it must find what it is for, and nothing else.

#[test]
fn the_constant_check_finds_an_undocumented_constant() {
    let src = "/// Why.\nconst A: f64 = 1.5;\n#[allow(dead_code)]\n// Why too.\nconst B: f64 = 2.5;\n\npub const C: f64 = 0.45;\nconst fn f() {}\n#[cfg(test)]\nmod tests {\n    const T: f64 = 3.0;\n}\n";
    assert_eq!(
        undocumented_constants(src),
        vec![(7, "pub const C: f64 = 0.45;".to_string())]
    );
}

#[test]
fn the_scanner_finds_a_bare_literal() {
    let src = "fn f(x: f64) -> f64 {\n    x.min(0.45 * x)\n}\n";
    let bare = scan_source("x.rs", src);
    assert_eq!(bare.len(), 1, "{bare:?}");
    assert_eq!(bare[0].literal, "0.45");
    assert_eq!(bare[0].line, 2);
    for src in [
        "fn f() -> u32 { 64 }",
        "fn f(x: f64) -> f64 { 1e-9 + x }",
        "fn f(x: f64) -> f64 { 3.0 * x }",
        "fn f(x: f64) -> f64 { x * 5_f64 }",
        "fn f() { for i in 0..10 {} }",
        "fn f(x: f64) -> f64 { x / 0.5 }",
        "fn f() -> f64 { let a = [1.0; 3]; a[0] }",
    ] {
        assert_eq!(scan_source("x.rs", src).len(), 1, "{src}");
    }
}

#[test]
fn the_scanner_lets_pass_what_is_not_a_bare_literal() {
    let src = r#"
//! A doc comment with 0.45 and 64.
/// 3.0 deviations.
pub const CAP: f64 = 0.45;
static TABLE: [f64; 3] = [0.1, 0.2, 0.3];
pub const S: P = P { a: 3.0, b: [4.0, 5.0] };
const fn helper() -> f64 { 0.0 }
impl Default for P {
    fn default() -> Self { Self { a: 3.0, b: [4.0, 5.0] } }
}
fn default_gain() -> f64 { 0.7 }
impl P {
    fn validate(&self) -> Result<(), String> { at_least("a", self.a, 0.5) }
}
fn f(x: f64, p: (f64, f64)) -> f64 {
    let s = "a string with 7.5 in it";
    let r = r"raw 9.0";
    let c = '9';
    /* a block comment with 33 */
    let y = 0.0 + 1.0 * 2.0 - 0 + 1 + 2 + 2.0_f64 + 1e0 + 0.5e1 * 0.0;
    for i in 0..2 {}
    x.max(CAP) + p.0 + p.1 + (x, x).1 + 1.max(2) as f64 + 2.
}
#[cfg(test)]
mod tests {
    #[test]
    fn t() { assert_eq!(0.45, 0.45); }
}
#[cfg(test)]
fn helper_for_tests() -> f64 { 17.0 }
"#;
    let bare = scan_source("x.rs", src);
    // `0.5e1` is 5: bare. Everything else is allowed.
    assert_eq!(bare.len(), 1, "{bare:?}");
    assert_eq!(bare[0].literal, "0.5e1");
}
