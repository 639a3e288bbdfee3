//! `cargo xtask tidy` (and ci's first step): rules about the repository's tracked files that
//! neither the compiler nor clippy checks, each a cheap text scan. It keeps clippy's
//! argument-count lint unsilenced, the fuzz harness in one shared crate instead of copies, the
//! repository standing alone (crates are top-level folders, nothing outside it is named),
//! source files small enough to read, terrain-demo's modules free of import cycles, and the
//! theses cited by author and year. Every problem is reported as `file:line: why`.

use crate::util::root;
use anyhow::{Context, Result, bail};
use std::collections::HashMap;
use std::fmt;
use std::process::Command;

/// This file: its rules' own patterns (and the fixtures of its tests) would match them.
const SELF: &str = "xtask/src/tidy.rs";

/// The text files tidy reads, by extension.
const TEXT_EXTENSIONS: [&str; 7] = ["rs", "md", "toml", "wgsl", "sh", "json", "yml"];

/// The most lines a `.rs` file may have.
const MAX_RS_LINES: usize = 1000;

/// The example of the whole frame an engine runs, and the most lines it may have (issue 33).
const ENGINE_FRAME: &str = "terrain-demo/examples/engine_frame.rs";
const ENGINE_FRAME_MAX_LINES: usize = 400;

/// Two `.rs` files this long or longer with the same content are a copy.
const MIN_COPY_LINES: usize = 40;

/// The folder beside the repository that nothing in it may name (spelt in two parts so that
/// this file does not name it either).
const OUTSIDE: &str = concat!("..", "/", "shared");

/// The clippy lint that must never be silenced.
const ARGUMENT_LINT: &str = "too_many_arguments";

/// One tracked text file: its path from the repository root (with `/`) and its content.
pub struct TrackedFile {
    pub path: String,
    pub text: String,
}

/// One broken rule, at a file and line (1-based).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    pub path: String,
    pub line: usize,
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}: {}", self.path, self.line, self.message)
    }
}

/// Checks every tracked text file; fails naming each problem.
pub fn tidy() -> Result<()> {
    let files = tracked_text_files()?;
    let problems = check(&files);
    for p in &problems {
        eprintln!("{p}");
    }
    if !problems.is_empty() {
        bail!(
            "tidy: {} problem(s) in the tracked files (listed above)",
            problems.len()
        );
    }
    eprintln!("tidy: {} tracked text files ok", files.len());
    Ok(())
}

/// The tracked files (`git ls-files`) with a [`TEXT_EXTENSIONS`] extension, outside target/.
/// A file deleted in the work tree but still tracked, or one that is not UTF-8, is skipped.
fn tracked_text_files() -> Result<Vec<TrackedFile>> {
    let output = Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(root())
        .output()
        .context("could not start git ls-files")?;
    if !output.status.success() {
        bail!(
            "`git ls-files` exited with {}: {}",
            output.status,
            String::from_utf8_lossy(&output.stderr).trim()
        );
    }
    let listing = String::from_utf8(output.stdout).context("git ls-files printed non-UTF-8")?;
    let mut files = Vec::new();
    for path in listing.split('\0').filter(|p| is_checked_path(p)) {
        match std::fs::read_to_string(root().join(path)) {
            Ok(text) => files.push(TrackedFile {
                path: path.to_owned(),
                text,
            }),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::InvalidData
                ) => {}
            Err(e) => return Err(e).with_context(|| format!("reading {path}")),
        }
    }
    Ok(files)
}

/// Whether tidy reads the file at `path`: a text extension, and not under target/.
fn is_checked_path(path: &str) -> bool {
    !path.starts_with("target/")
        && path
            .rsplit_once('.')
            .is_some_and(|(_, ext)| TEXT_EXTENSIONS.contains(&ext))
}

/// Every rule over `files`, sorted by file and line.
pub fn check(files: &[TrackedFile]) -> Vec<Problem> {
    let others: Vec<&TrackedFile> = files.iter().filter(|f| f.path != SELF).collect();
    let mut problems = Vec::new();
    for f in &others {
        if f.path.ends_with(".rs") {
            problems.extend(argument_lint_allowances(&f.path, &f.text));
        }
        problems.extend(outside_paths(&f.path, &f.text));
        problems.extend(theses_by_number(&f.path, &f.text));
        if f.path.ends_with(".rs") {
            problems.extend(lone_compile_fail(&f.path, &f.text));
        }
    }
    problems.extend(harness_copies(&others));
    problems.extend(crate::import_cycles::import_cycles(&others));
    for f in files {
        problems.extend(long_file(&f.path, &f.text));
    }
    problems.sort_by(|a, b| (&a.path, a.line).cmp(&(&b.path, b.line)));
    problems
}

/// The 1-based line of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text[..offset].matches('\n').count() + 1
}

/// Rule (a): `too_many_arguments` inside an `allow(` or `expect(` attribute of a `.rs` file.
/// A function with that many arguments wants a struct of them instead.
fn argument_lint_allowances(path: &str, text: &str) -> Vec<Problem> {
    text.match_indices(ARGUMENT_LINT)
        .filter(|&(i, _)| {
            let before = &text[..i];
            // The attribute the lint name is in: the last `#[` / `#![` before it, not closed.
            let Some(start) = before.rfind("#[").max(before.rfind("#![")) else {
                return false;
            };
            let attr = &before[start..];
            !attr.contains(']') && (attr.contains("allow(") || attr.contains("expect("))
        })
        .map(|(i, _)| Problem {
            path: path.to_owned(),
            line: line_of(text, i),
            message: format!(
                "clippy::{ARGUMENT_LINT} is silenced: pass a struct of the arguments instead"
            ),
        })
        .collect()
}

/// Rule (b): a copied fuzz harness. A `harness.rs` under a crate's `tests/` folder (the
/// harness lives in one shared crate), or two `.rs` files of [`MIN_COPY_LINES`] lines or more
/// with the same content (reported at the second, naming the first).
fn harness_copies(files: &[&TrackedFile]) -> Vec<Problem> {
    let mut problems = Vec::new();
    let mut first_of: HashMap<&str, &str> = HashMap::new();
    for f in files.iter().filter(|f| f.path.ends_with(".rs")) {
        let mut parts = f.path.split('/');
        let name = parts.next_back().unwrap_or_default();
        if name == "harness.rs" && parts.any(|dir| dir == "tests") {
            problems.push(Problem {
                path: f.path.clone(),
                line: 1,
                message: "a copy of the fuzz harness: use the shared one \
                          (terrain-test-support, xtask/test-support) instead"
                    .into(),
            });
        }
        let lines = f.text.lines().count();
        if lines < MIN_COPY_LINES {
            continue;
        }
        match first_of.get(f.text.as_str()) {
            Some(first) => problems.push(Problem {
                path: f.path.clone(),
                line: 1,
                message: format!("the same {lines} lines as {first}: keep one copy and share it"),
            }),
            None => {
                first_of.insert(&f.text, &f.path);
            }
        }
    }
    problems
}

/// Rule (c): a mention of [`OUTSIDE`] (the folder beside the repository) or of a path starting with `crates/`. The repository
/// stands alone and its crates are top-level folders.
fn outside_paths(path: &str, text: &str) -> Vec<Problem> {
    let mut problems = Vec::new();
    for (i, _) in text.match_indices(OUTSIDE) {
        problems.push(Problem {
            path: path.to_owned(),
            line: line_of(text, i),
            message: format!(
                "names `{OUTSIDE}`, outside the repository: the repository stands alone"
            ),
        });
    }
    for (i, _) in text.match_indices("crates/") {
        // Only where a path starts: not `foo-crates/`, `registry/crates/` or `.crates/`.
        let starts_path = text[..i]
            .chars()
            .next_back()
            .is_none_or(|c| !(c.is_alphanumeric() || "_-./".contains(c)));
        if starts_path {
            problems.push(Problem {
                path: path.to_owned(),
                line: line_of(text, i),
                message: "names a path under `crates/`: the crates are top-level folders".into(),
            });
        }
    }
    problems
}

/// Rule (e): a thesis cited by its number in the project's seed list ("seed 000") instead
/// of by author and year ("Flower 2010, sec. 3.2"): the number means nothing to a reader
/// without docs/REFERENCES.md at hand.
fn theses_by_number(path: &str, text: &str) -> Vec<Problem> {
    let lower = text.to_ascii_lowercase();
    let mut problems = Vec::new();
    for (i, _) in lower.match_indices("seed") {
        let rest = &lower.as_bytes()[i + 4..];
        let numbered = rest.len() >= 4
            && matches!(rest[0], b' ' | b'-')
            && rest[1..4].iter().all(u8::is_ascii_digit)
            && rest.get(4).is_none_or(|c| !c.is_ascii_digit());
        if numbered {
            problems.push(Problem {
                path: path.to_owned(),
                line: line_of(text, i),
                message: "cites a thesis by number: cite it by author and year with the section \
                          (e.g. `Flower 2010, sec. 3.2.1`; docs/REFERENCES.md)"
                    .into(),
            });
        }
    }
    problems
}

/// Rule (f): a `compile_fail` doctest without a companion. Such a test passes for any
/// compile error, a stale argument list included, so it proves nothing unless the next block
/// of the same doc comment compiles (plain, `rust`, `no_run` or `should_panic`) and differs
/// from it in exactly one line: then that line is why it fails. (Rustdoc checks an error code
/// given as `compile_fail,E0277` only on nightly.)
fn lone_compile_fail(path: &str, text: &str) -> Vec<Problem> {
    let mut problems = Vec::new();
    for comment in doc_comments(text) {
        let blocks = code_blocks(&comment);
        for (i, block) in blocks.iter().enumerate() {
            if !block.attrs.split(',').any(|a| a.trim() == "compile_fail") {
                continue;
            }
            let companion = blocks.get(i + 1).filter(|next| {
                next.attrs.split(',').all(|a| {
                    matches!(
                        a.trim(),
                        "" | "rust" | "no_run" | "should_panic" | "edition2024"
                    )
                }) && next.lines.len() == block.lines.len()
                    && next
                        .lines
                        .iter()
                        .zip(&block.lines)
                        .filter(|(a, b)| a != b)
                        .count()
                        == 1
            });
            if companion.is_none() {
                problems.push(Problem {
                    path: path.to_owned(),
                    line: block.line,
                    message: "a compile_fail doctest needs a companion: the next block of the comment must compile \
                              and differ from it in one line (the reason it fails), or any stale call \
                              would pass it"
                        .into(),
                });
            }
        }
    }
    problems
}

/// A doc comment's text lines (`///` or `//!` prefix and one space removed) with their 1-based
/// line numbers, one entry per run of consecutive doc lines.
fn doc_comments(text: &str) -> Vec<Vec<(usize, &str)>> {
    let mut comments = Vec::new();
    let mut current: Vec<(usize, &str)> = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        match trimmed
            .strip_prefix("///")
            .or_else(|| trimmed.strip_prefix("//!"))
        {
            Some(rest) => current.push((n + 1, rest.strip_prefix(' ').unwrap_or(rest))),
            None if !current.is_empty() => comments.push(std::mem::take(&mut current)),
            None => {}
        }
    }
    if !current.is_empty() {
        comments.push(current);
    }
    comments
}

/// A fenced code block of a doc comment.
struct CodeBlock<'a> {
    /// What follows the opening fence (`compile_fail`, `no_run`, ...).
    attrs: &'a str,
    /// The line of the opening fence.
    line: usize,
    /// The block's lines, fences excluded.
    lines: Vec<&'a str>,
}

/// The fenced blocks of one doc comment, in order (an unclosed one runs to its end).
fn code_blocks<'a>(comment: &[(usize, &'a str)]) -> Vec<CodeBlock<'a>> {
    let mut blocks = Vec::new();
    let mut open: Option<CodeBlock<'a>> = None;
    for &(line, text) in comment {
        let fence = text.trim_start().strip_prefix("```");
        match (&mut open, fence) {
            (None, Some(attrs)) => {
                open = Some(CodeBlock {
                    attrs: attrs.trim(),
                    line,
                    lines: Vec::new(),
                })
            }
            (Some(_), Some(_)) => blocks.extend(open.take()),
            (Some(block), None) => block.lines.push(text),
            (None, None) => {}
        }
    }
    blocks.extend(open);
    blocks
}

/// Rule (d): a `.rs` file over [`MAX_RS_LINES`] lines (a generated one, marked `@generated`
/// in its first lines, is exempt). Split it into modules of one purpose each.
fn long_file(path: &str, text: &str) -> Option<Problem> {
    let lines = text.lines().count();
    if path == ENGINE_FRAME && lines > ENGINE_FRAME_MAX_LINES {
        return Some(Problem {
            path: path.to_owned(),
            line: ENGINE_FRAME_MAX_LINES + 1,
            message: format!(
                "{lines} lines, over {ENGINE_FRAME_MAX_LINES}: the whole frame an engine copies \
                 must stay short (move what it repeats into the libraries)"
            ),
        });
    }
    let generated = text.lines().take(5).any(|l| l.contains("@generated"));
    (path.ends_with(".rs") && lines > MAX_RS_LINES && !generated).then(|| Problem {
        path: path.to_owned(),
        line: MAX_RS_LINES + 1,
        message: format!(
            "{lines} lines, over {MAX_RS_LINES}: split it into modules of one purpose each"
        ),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A tracked file of `path` holding `text` (the import-cycle tests use it too).
    pub(crate) fn file(path: &str, text: &str) -> TrackedFile {
        TrackedFile {
            path: path.into(),
            text: text.into(),
        }
    }

    /// `n` distinct lines.
    fn lines(n: usize) -> String {
        (0..n).map(|i| format!("let x{i} = {i};\n")).collect()
    }

    #[test]
    fn silenced_argument_lint_is_found_at_its_line() {
        let text = "fn a() {}\n#[allow(clippy::too_many_arguments)]\nfn b() {}\n\
                    #[cfg_attr(test, expect(\n    clippy::too_many_arguments,\n))]\nfn c() {}\n\
                    #![allow(dead_code, clippy::too_many_arguments)]\n";
        let found = argument_lint_allowances("a/src/lib.rs", text);
        let at: Vec<usize> = found.iter().map(|p| p.line).collect();
        assert_eq!(at, [2, 5, 8]);
        assert_eq!(
            found[0].to_string(),
            "a/src/lib.rs:2: clippy::too_many_arguments is silenced: pass a struct of the \
             arguments instead"
        );
    }

    #[test]
    fn argument_lint_named_outside_an_allowance_is_fine() {
        let text = "// clippy's too_many_arguments: we pass structs\n\
                    #[derive(Debug)]\nstruct S; // too_many_arguments\n\
                    #[warn(clippy::too_many_arguments)]\nfn f() {}\n";
        assert_eq!(argument_lint_allowances("a/src/lib.rs", text), []);
        // Only `.rs` files are read for it.
        let toml = file("a/Cargo.toml", "#[allow(clippy::too_many_arguments)]\n");
        assert_eq!(check(&[toml]), []);
    }

    #[test]
    fn copied_harness_is_found_by_name() {
        let files = [
            file("terrain-core/tests/fuzz/harness.rs", "pub fn run() {}\n"),
            file("terrain-core/tests/fuzz.rs", "mod fuzz;\n"),
            file("xtask/test-support/src/harness.rs", "pub fn run() {}\n"),
        ];
        let found = check(&files);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].path, "terrain-core/tests/fuzz/harness.rs");
        assert_eq!(found[0].line, 1);
    }

    #[test]
    fn identical_long_files_are_copies_and_short_or_different_ones_are_not() {
        let long = lines(MIN_COPY_LINES);
        let files = [
            file("a/src/x.rs", &long),
            file("b/src/x.rs", &long),
            file("c/src/short.rs", "mod a;\n"),
            file("d/src/short.rs", "mod a;\n"),
            file("e/src/other.rs", &lines(MIN_COPY_LINES + 1)),
            file("f/notes.md", &long),
        ];
        let found = check(&files);
        assert_eq!(found.len(), 1, "{found:?}");
        assert_eq!(found[0].path, "b/src/x.rs");
        assert!(found[0].message.contains("a/src/x.rs"), "{}", found[0]);
    }

    #[test]
    fn paths_outside_the_repository_are_found() {
        let text = format!("see {OUTSIDE}/lib\n\nthe crate `crates/terrain-core/src`\n");
        let found = outside_paths("docs/x.md", &text);
        let at: Vec<usize> = found.iter().map(|p| p.line).collect();
        assert_eq!(at, [1, 3]);
        assert!(found[1].message.contains("top-level"), "{}", found[1]);
        let yml = file(".github/ci.yml", "run: cd crates/lod\n");
        assert_eq!(check(&[yml]).len(), 1);
    }

    #[test]
    fn crates_not_starting_a_path_is_fine() {
        let text = "publish to crates.io; ~/.cargo/registry/crates/x; my-crates/ and sub.crates/\n\
                    the crates are top-level folders\n";
        assert_eq!(outside_paths("README.md", text), []);
        // This file's own patterns and fixtures are not checked against it.
        let me = file(
            SELF,
            &format!("{OUTSIDE} crates/x #[allow(clippy::too_many_arguments)]\n"),
        );
        assert_eq!(check(&[me]), []);
    }

    #[test]
    fn theses_cited_by_number_are_found_and_rng_seeds_are_not() {
        let text =
            "// as in Seed 001 sec. 4\nlet seed = 42; // --seed 7, seed 12345\n// seed-002\n";
        let lines: Vec<usize> = theses_by_number("a.rs", text)
            .iter()
            .map(|p| p.line)
            .collect();
        assert_eq!(lines, vec![1, 3]);
        assert!(theses_by_number("b.md", "Flower 2010, sec. 3.2.1; seed 7").is_empty());
    }

    #[test]
    fn long_rs_files_are_found_and_others_are_not() {
        let long = lines(MAX_RS_LINES + 1);
        let found = check(&[file("a/src/big.rs", &long)]);
        assert_eq!(found.len(), 1);
        assert_eq!(
            found[0].to_string(),
            "a/src/big.rs:1001: 1001 lines, over 1000: split it into modules of one purpose each"
        );
        let generated = format!("// @generated by a tool\n{long}");
        assert_eq!(long_file("a/src/gen.rs", &generated), None);
        assert_eq!(long_file("a/src/ok.rs", &lines(MAX_RS_LINES)), None);
        assert_eq!(long_file("docs/long.md", &long), None);
        // The rule holds for this file too.
        assert!(long_file(SELF, &long).is_some());
    }

    #[test]
    fn checked_paths_are_text_files_outside_target() {
        assert!(is_checked_path("terrain-core/src/lib.rs"));
        assert!(is_checked_path("shaders/clipmap.wgsl"));
        assert!(is_checked_path(".github/workflows/ci.yml"));
        assert!(!is_checked_path("target/debug/build/x.rs"));
        assert!(!is_checked_path("docs/frame.png"));
        assert!(!is_checked_path(".ci/run"));
    }

    #[test]
    fn compile_fail_doctests_need_a_companion_one_line_apart() {
        let good = "/// ```compile_fail\n/// let a: u32 = f();\n/// g(a);\n/// ```\n///\n\
                    /// ```no_run\n/// let a: u16 = f();\n/// g(a);\n/// ```\nfn x() {}\n";
        assert_eq!(lone_compile_fail("a/src/lib.rs", good), []);
        // No companion, one in another comment, or one differing in two lines.
        let lone = "fn y() {}\n/// ```compile_fail\n/// g(1);\n/// ```\nfn x() {}\n";
        let split = "/// ```compile_fail\n/// g(1);\n/// ```\nfn x() {}\n\
                     /// ```\n/// g(2);\n/// ```\nfn z() {}\n";
        let two = "//! ```compile_fail\n//! let a = 1;\n//! g(a);\n//! ```\n\
                   //! ```\n//! let a = 2;\n//! h(a);\n//! ```\n";
        let ignored =
            "/// ```compile_fail\n/// g(1);\n/// ```\n/// ```ignore\n/// g(2);\n/// ```\n";
        for (text, line) in [(lone, 2), (split, 1), (two, 1), (ignored, 1)] {
            let found = lone_compile_fail("a/src/lib.rs", text);
            assert_eq!(found.len(), 1, "{text}");
            assert_eq!(found[0].line, line, "{text}");
        }
    }

    #[test]
    fn the_engine_frame_example_stays_within_its_lines() {
        assert!(long_file(ENGINE_FRAME, &lines(400)).is_none());
        let p = long_file(ENGINE_FRAME, &lines(401)).unwrap();
        assert_eq!(p.line, 401);
        assert!(long_file("terrain-demo/examples/other.rs", &lines(401)).is_none());
    }
}
