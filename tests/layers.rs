//! The layers of `docs/ARCHITECTURE.md` ("Layers"), checked from the source: a module that
//! names what its layer must not know fails here, with the file, the line and the rule.
//!
//! Test code (`#[cfg(test)] mod ... { }` and `tests.rs` files) may compose layers and is not
//! checked; comments are not checked.

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
