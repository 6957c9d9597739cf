//! The layers of `docs/ARCHITECTURE.md` ("Layers"), checked from the source: a module that
//! names what its layer must not know fails here, with the file, the line and the rule.
//!
//! Test code (`#[cfg(test)] mod ... { }` and `tests.rs` files) may compose layers and is not
//! checked; comments are not checked.
//!
//! The same document's "Tests" section names every test, benchmark and fuzz-target file by its
//! path; a file it does not name fails here too.

use std::path::{Path, PathBuf};

/// One rule: the files under `paths`, but those in `except`, never name any of `forbidden`
/// outside their tests.
struct Rule {
    what: &'static str,
    paths: &'static [&'static str],
    except: &'static [&'static str],
    forbidden: &'static [&'static str],
}

/// What I/O looks like in Rust source: async runtimes, servers, files, sockets, threads, clocks.
const IO: &[&str] = &[
    "tokio::",
    "tokio_util::",
    "axum",
    "foxglove::",
    "std::fs",
    "std::net",
    "std::thread",
    "std::time::Instant",
    "SystemTime",
    "File::",
];

const RULES: &[Rule] = &[
    Rule {
        what: "the simulation core (physics, sensors, devices, engine, plant) knows nothing of \
               tokio, axum, files, the recorder, the daemon or the view",
        paths: &["src/physics", "src/sensors", "src/devices", "src/engine"],
        except: &[],
        forbidden: &[
            "crate::daemon",
            "crate::view",
            "crate::cli",
            "crate::record::Recorder",
            "crate::record::RecordHandle",
            "crate::transport::pty",
            "crate::transport::serial",
            "crate::transport::symlink",
            "crate::transport::latency",
            "crate::transport::timer",
        ],
    },
    Rule {
        what: "the simulation core does no I/O",
        paths: &["src/physics", "src/sensors", "src/devices", "src/engine"],
        except: &[],
        forbidden: IO,
    },
    Rule {
        what: "the transcript decoder is sans-IO and knows nothing of who reads it",
        paths: &["src/transcript.rs"],
        except: &[],
        forbidden: &["crate::view", "crate::gap", "crate::daemon", "crate::cli"],
    },
    Rule {
        what: "the transcript decoder does no I/O",
        paths: &["src/transcript.rs"],
        except: &[],
        forbidden: IO,
    },
    Rule {
        what: "the daemon knows nothing of the view, Foxglove or the CLI: it offers an observer",
        paths: &["src/daemon"],
        except: &[],
        forbidden: &["crate::view", "crate::cli", "axum", "foxglove"],
    },
    Rule {
        what: "the view knows nothing of the CLI",
        paths: &["src/view"],
        except: &[],
        forbidden: &["crate::cli"],
    },
    Rule {
        what: "the protocol crate is sans-IO: it never opens a port, sleeps or reads a clock",
        paths: &["firmware-protocol/src"],
        // The optional adapter of the decoder to tokio-util's codec traits (feature
        // `tokio-codec`): it does no I/O itself, a `FramedRead` around it does.
        except: &["firmware-protocol/src/codec.rs"],
        forbidden: IO,
    },
];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    if dir.extension().is_some_and(|e| e == "rs") {
        out.push(dir.to_path_buf());
        return;
    }
    let entries = std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    for entry in entries {
        let path = entry.expect("a directory entry").path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The lines of `text` outside test modules, with their numbers, comments cut off.
fn code_lines(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut lines = text.lines().enumerate().peekable();
    while let Some((i, line)) = lines.next() {
        let trimmed = line.trim();
        if trimmed == "#[cfg(test)]"
            && lines.peek().is_some_and(|(_, next)| {
                let next = next.trim_start();
                (next.starts_with("mod ") || next.starts_with("pub(crate) mod "))
                    && next.ends_with('{')
            })
        {
            // Skip the test module, braces counted line by line.
            let mut depth = 0i64;
            for (_, l) in lines.by_ref() {
                depth += l.matches('{').count() as i64 - l.matches('}').count() as i64;
                if depth <= 0 && l.contains('}') {
                    break;
                }
            }
            continue;
        }
        let code = match line.find("//") {
            Some(at) => &line[..at],
            None => line,
        };
        if !code.trim().is_empty() {
            out.push((i + 1, code.to_string()));
        }
    }
    out
}

/// Every rule broken in the source under `root`: `file:line: `name`: rule`.
fn violations(root: &Path, rules: &[Rule]) -> Vec<String> {
    let mut found = Vec::new();
    for rule in rules {
        let mut files = Vec::new();
        for path in rule.paths {
            rust_files(&root.join(path), &mut files);
        }
        assert!(!files.is_empty(), "no source under {:?}", rule.paths);
        for file in files {
            let shown = file.strip_prefix(root).unwrap_or(&file);
            if file.file_name().is_some_and(|n| n == "tests.rs")
                || rule.except.iter().any(|e| shown == Path::new(e))
            {
                continue;
            }
            let text = std::fs::read_to_string(&file)
                .unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            for (line, code) in code_lines(&text) {
                for name in rule.forbidden {
                    if code.contains(name) {
                        found.push(format!(
                            "{}:{line}: `{name}`: {}",
                            shown.display(),
                            rule.what
                        ));
                    }
                }
            }
        }
    }
    found
}

#[test]
fn no_layer_knows_a_layer_above_it() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let found = violations(root, RULES);
    assert!(found.is_empty(), "back-edges:\n{}", found.join("\n"));
}

/// The check finds a back-edge where there is one, skips test modules and comments, and
/// finds code after a test module.
#[test]
fn the_check_finds_a_back_edge_and_skips_tests_and_comments() {
    let dir = eyebot_test_support::TempDir::new("layers");
    let core = dir.path().join("src/engine");
    std::fs::create_dir_all(&core).expect("mkdir");
    std::fs::write(
        core.join("mod.rs"),
        "//! Never uses tokio.\nuse crate::physics; // not crate::view\n\
         #[cfg(test)]\nmod tests {\n    use crate::daemon::config;\n    fn f() { if true { } }\n}\n\
         fn after() { let _ = crate::view::wire::WireWatch::new(); }\n",
    )
    .expect("write");
    let rules = [Rule {
        what: "test rule",
        paths: &["src/engine"],
        except: &[],
        forbidden: &["crate::view", "crate::daemon", "tokio"],
    }];
    let found = violations(dir.path(), &rules);
    assert_eq!(found.len(), 1, "{found:?}");
    assert!(
        found[0].starts_with("src/engine/mod.rs:8: `crate::view`"),
        "{found:?}"
    );
}

/// The folders whose `*.rs` files cargo builds as test binaries, benchmarks or fuzz targets
/// (their top level only: a subfolder such as `tests/support/` is a module or a crate).
const TEST_DIRS: &[&str] = &[
    "tests",
    "benches",
    "fuzz/fuzz_targets",
    "pty-tests/tests",
    "pty-tests/benches",
    "firmware-protocol/tests",
    "firmware-protocol/benches",
    "firmware-protocol/fuzz/fuzz_targets",
];

/// The `## Tests` section of the architecture document `doc`, up to the next `## ` heading.
fn tests_section(doc: &str) -> &str {
    let start = doc
        .find("\n## Tests\n")
        .expect("docs/ARCHITECTURE.md has a `## Tests` section");
    let rest = &doc[start + 1..];
    match rest[1..].find("\n## ") {
        Some(end) => &rest[..end + 1],
        None => rest,
    }
}

/// Whether `text` names `path` whole: not as the tail of a longer path
/// (`tests/fuzz_corpora.rs` inside `firmware-protocol/tests/fuzz_corpora.rs`) and not as the
/// head of a longer name.
fn names_path(text: &str, path: &str) -> bool {
    text.match_indices(path).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + path.len()..].chars().next();
        !before.is_some_and(|c| c.is_alphanumeric() || "/_-.".contains(c))
            && !after.is_some_and(|c| c.is_alphanumeric() || c == '_')
    })
}

/// The `*.rs` files at the top of each of `dirs` under `root` that `text` does not name, as
/// paths relative to `root` (`tests/gap_slurm.rs`).
fn unnamed_test_files(root: &Path, dirs: &[&str], text: &str) -> Vec<String> {
    let mut missing = Vec::new();
    for dir in dirs {
        let entries = std::fs::read_dir(root.join(dir))
            .unwrap_or_else(|e| panic!("{}: {e}", root.join(dir).display()));
        let mut files: Vec<String> = entries
            .map(|entry| entry.expect("a directory entry").path())
            .filter(|path| path.is_file() && path.extension().is_some_and(|e| e == "rs"))
            .map(|path| {
                let name = path.file_name().expect("a file name").to_string_lossy();
                format!("{dir}/{name}")
            })
            .collect();
        assert!(
            !files.is_empty(),
            "no `*.rs` file in {dir}: if the folder moved, update TEST_DIRS in tests/layers.rs"
        );
        files.sort();
        missing.extend(files.into_iter().filter(|file| !names_path(text, file)));
    }
    missing
}

#[test]
fn every_test_file_is_named_in_the_architecture() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc_path = root.join("docs/ARCHITECTURE.md");
    let doc = std::fs::read_to_string(&doc_path)
        .unwrap_or_else(|e| panic!("{}: {e}", doc_path.display()));
    let missing = unnamed_test_files(root, TEST_DIRS, tests_section(&doc));
    assert!(
        missing.is_empty(),
        "not named in the \"Tests\" section of docs/ARCHITECTURE.md:\n  {}\n\
         add a row for each to its crate's table there: | `PATH` | what it checks |",
        missing.join("\n  ")
    );
}

/// The name check reports a file the text does not name, wants each path whole, and lists
/// only the `*.rs` files at the top of each folder.
#[test]
fn the_name_check_wants_each_path_whole() {
    let dir = eyebot_test_support::TempDir::new("layers-names");
    for file in [
        "tests/named.rs",
        "tests/fuzz_corpora.rs",
        "tests/gap.rs",
        "tests/unnamed.rs",
        "tests/data.txt",
        "tests/common/mod.rs",
        "crate/tests/fuzz_corpora.rs",
    ] {
        let path = dir.path().join(file);
        std::fs::create_dir_all(path.parent().expect("a parent")).expect("mkdir");
        std::fs::write(&path, "").expect("write");
    }
    let text = "| `tests/named.rs` | ... |\n| `crate/tests/fuzz_corpora.rs` | ... |\n\
                | `tests/gap.rsx` | ... |\n";
    let missing = unnamed_test_files(dir.path(), &["tests", "crate/tests"], text);
    assert_eq!(
        missing,
        ["tests/fuzz_corpora.rs", "tests/gap.rs", "tests/unnamed.rs"]
    );
    let doc = "# A\n\n## Tests\n\n`tests/in.rs`\n\n## Known limits\n\n`tests/out.rs`\n";
    assert!(names_path(tests_section(doc), "tests/in.rs"));
    assert!(!names_path(tests_section(doc), "tests/out.rs"));
}
