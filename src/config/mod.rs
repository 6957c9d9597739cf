//! Configuration: TOML text in, checked settings out.
//!
//! Every config file goes through two stages (as helix's `helix-term` config does):
//!
//! 1. **Raw**: the text is parsed into a `Raw*` struct with `#[serde(deny_unknown_fields)]`,
//!    so a misspelt key is an error, not a silently ignored setting.
//! 2. **Resolved**: the raw struct is checked (units, ranges, cross-field rules) and turned
//!    into the typed settings the rest of the crate uses.
//!
//! Loaders take text, never paths: a [`ConfigSource`] supplies the text of a named file, either
//! from the copies embedded at build time ([`Embedded`]) or from a directory ([`Directory`]).
//! Errors name the file, the line and the key ([`ConfigError`]).

use std::borrow::Cow;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;

mod embedded {
    include!(concat!(env!("OUT_DIR"), "/embedded_configs.rs"));
}
pub use embedded::EMBEDDED_CONFIGS;

/// The name, inside any [`ConfigSource`], of the daemon's default configuration.
pub const DEFAULT_CONFIG: &str = "default.toml";

/// The largest configuration file read: the shipped ones are a few KiB, and `/dev/zero`
/// given as a file must cost an error, not memory.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Reads a configuration file with bounded memory and without blocking: opened non-blocking
/// (a FIFO without a writer does not hang the open), refused unless it is a regular file,
/// refused past [`MAX_CONFIG_BYTES`]. The error says what was found and what was expected.
pub fn read_config_file(path: &Path) -> Result<String, String> {
    use std::io::Read;
    use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
        .map_err(|e| e.to_string())?;
    let kind = file.metadata().map_err(|e| e.to_string())?.file_type();
    if !kind.is_file() {
        let found = if kind.is_dir() {
            "a directory"
        } else if kind.is_fifo() {
            "a FIFO"
        } else if kind.is_char_device() || kind.is_block_device() {
            "a device"
        } else {
            "not a regular file"
        };
        return Err(format!("{found}; expected a regular TOML file"));
    }
    let mut bytes = Vec::new();
    file.take(MAX_CONFIG_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > MAX_CONFIG_BYTES {
        return Err(format!(
            "larger than {MAX_CONFIG_BYTES} bytes; expected a TOML file of a few KiB"
        ));
    }
    String::from_utf8(bytes).map_err(|e| format!("not UTF-8 text ({e}); expected a TOML file"))
}

/// A configuration problem. Every variant names the input it came from.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The text is not valid TOML, has an unknown key, or a value of the wrong type.
    #[error("{origin}:{line}:{column}: {message}")]
    Syntax {
        origin: String,
        line: usize,
        column: usize,
        message: String,
    },
    /// The TOML is well formed but a value is out of range or inconsistent.
    #[error("{origin}:{} `{key}`: {message}", line.map_or_else(String::new, |l| format!("{l}:")))]
    Invalid {
        origin: String,
        key: String,
        line: Option<usize>,
        message: String,
    },
    /// A value given in place of a configuration key (a command-line option) is out of
    /// range.
    #[error("{option} (in place of `{key}`): {message}")]
    Override {
        option: String,
        key: String,
        message: String,
    },
    /// A file named by the user, or referenced from another config file, cannot be read.
    #[error("{origin}: cannot read config `{name}`: {reason}")]
    Unreadable {
        origin: String,
        name: String,
        reason: String,
    },
    /// A file named by a key of another configuration failed to load.
    #[error("`{key}` = \"{name}\" (in {origin}): {source}")]
    Referenced {
        origin: String,
        key: String,
        name: String,
        #[source]
        source: Box<ConfigError>,
    },
}

/// Supplies the text of configuration files by name (a path relative to the source's root,
/// with `/` separators, e.g. `vehicles/mako.toml`).
pub trait ConfigSource {
    /// The text of `name`.
    fn read(&self, name: &str) -> Result<Cow<'static, str>, ConfigError>;
    /// A human-readable origin for `name`, used in error messages.
    fn describe(&self, name: &str) -> String;
}

/// The files under `configs/` as they were at build time.
#[derive(Debug, Clone, Copy, Default)]
pub struct Embedded;

impl ConfigSource for Embedded {
    fn read(&self, name: &str) -> Result<Cow<'static, str>, ConfigError> {
        EMBEDDED_CONFIGS
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, text)| Cow::Borrowed(*text))
            .ok_or_else(|| ConfigError::Unreadable {
                origin: "<embedded>".to_string(),
                name: name.to_string(),
                reason: format!(
                    "no such embedded file; embedded are: {}",
                    EMBEDDED_CONFIGS
                        .iter()
                        .map(|(n, _)| *n)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            })
    }

    fn describe(&self, name: &str) -> String {
        format!("<embedded>/{name}")
    }
}

/// Files in a directory on disk (references inside them resolve against the same directory).
#[derive(Debug, Clone)]
pub struct Directory {
    root: PathBuf,
}

impl Directory {
    pub fn new(root: impl Into<PathBuf>) -> Self {
        Self { root: root.into() }
    }

    /// The directory holding `file` and the file's name inside it, so a user's
    /// `--config some/dir/run.toml` resolves its references beside it.
    pub fn for_file(file: &Path) -> (Self, String) {
        let root = file.parent().map(Path::to_path_buf).unwrap_or_default();
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        (Self::new(root), name)
    }

    pub fn root(&self) -> &Path {
        &self.root
    }
}

impl ConfigSource for Directory {
    fn read(&self, name: &str) -> Result<Cow<'static, str>, ConfigError> {
        let path = self.root.join(name);
        read_config_file(&path)
            .map(Cow::Owned)
            .map_err(|reason| ConfigError::Unreadable {
                origin: path.display().to_string(),
                name: name.to_string(),
                reason,
            })
    }

    fn describe(&self, name: &str) -> String {
        self.root.join(name).display().to_string()
    }
}

/// The one rule for the files a configuration names (`vehicle`, `world`, `sensors`, an
/// experiment's model files): read beside the configuration on disk, and when no file of
/// that name is there, the embedded copy of the same name (the files under `configs/` at
/// build time). A file that is there but cannot be read or parsed is an error, never
/// replaced by the embedded copy. An error names both places looked in.
#[derive(Debug, Clone)]
pub struct BesideOrEmbedded {
    /// `None` for an embedded configuration: its files are the embedded ones.
    dir: Option<Directory>,
    /// The configuration file itself, named on the command line: read from disk only, so a
    /// mistyped path is an error rather than the embedded file of that name.
    top: Option<String>,
}

impl BesideOrEmbedded {
    pub fn new(dir: Directory) -> Self {
        Self {
            dir: Some(dir),
            top: None,
        }
    }

    /// The source of the files `file` names, and `file`'s name in it: its directory on disk,
    /// with the embedded configs behind it. A `file` that does not exist on disk but whose
    /// path ends in an embedded name (`configs/experiments/acceleration.toml` outside the
    /// clone) is that embedded file.
    pub fn for_file(file: &Path) -> (Self, String) {
        if !file.exists()
            && let Some(name) = embedded_name_of(file)
        {
            return (
                Self {
                    dir: None,
                    top: None,
                },
                name,
            );
        }
        let (dir, name) = Directory::for_file(file);
        let source = Self {
            dir: Some(dir),
            top: Some(name.clone()),
        };
        (source, name)
    }

    /// The directory on disk, if the configuration is there.
    pub fn root(&self) -> Option<&Path> {
        self.dir.as_ref().map(Directory::root)
    }

    /// The directory on disk when it holds an entry `name`.
    fn on_disk(&self, name: &str) -> Option<&Directory> {
        self.dir
            .as_ref()
            .filter(|d| std::fs::symlink_metadata(d.root.join(name)).is_ok())
    }
}

/// The embedded config that `file` names by its path in the clone (`configs/worlds/pool.toml`
/// or `.../configs/worlds/pool.toml` -> `worlds/pool.toml`), if any. Only a path through
/// `configs/` counts: a mistyped `my/default.toml` is an error, not the embedded default.
fn embedded_name_of(file: &Path) -> Option<String> {
    let text = file.to_string_lossy();
    EMBEDDED_CONFIGS
        .iter()
        .map(|(n, _)| *n)
        .find(|n| text == format!("configs/{n}") || text.ends_with(&format!("/configs/{n}")))
        .map(str::to_string)
}

impl ConfigSource for BesideOrEmbedded {
    fn read(&self, name: &str) -> Result<Cow<'static, str>, ConfigError> {
        if let Some(dir) = self.on_disk(name) {
            return dir.read(name);
        }
        if let Some(dir) = &self.dir
            && self.top.as_deref() == Some(name)
        {
            return dir.read(name);
        }
        let beside = self.dir.as_ref().map_or_else(
            || "no file on disk (the configuration is embedded)".to_string(),
            |d| {
                format!(
                    "{} (files a configuration names are read beside it)",
                    d.describe(name)
                )
            },
        );
        Embedded.read(name).map_err(|_| ConfigError::Unreadable {
            origin: self
                .dir
                .as_ref()
                .map_or_else(|| Embedded.describe(name), |d| d.describe(name)),
            name: name.to_string(),
            reason: format!(
                "no such file; looked for {beside} and for an embedded `{name}` (embedded are: {})",
                EMBEDDED_CONFIGS
                    .iter()
                    .map(|(n, _)| *n)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        })
    }

    fn describe(&self, name: &str) -> String {
        match self.on_disk(name) {
            Some(dir) => dir.describe(name),
            None => Embedded.describe(name),
        }
    }
}

/// One TOML document with its origin, able to map keys and byte offsets to line numbers.
#[derive(Debug)]
pub struct Document<'a> {
    origin: String,
    text: &'a str,
}

impl<'a> Document<'a> {
    /// `origin` names the input in error messages (a path, or `<embedded>/default.toml`).
    pub fn new(origin: impl Into<String>, text: &'a str) -> Self {
        Self {
            origin: origin.into(),
            text,
        }
    }

    pub fn origin(&self) -> &str {
        &self.origin
    }

    /// Parses the whole document into a raw struct.
    pub fn parse<T: DeserializeOwned>(&self) -> Result<T, ConfigError> {
        toml::from_str(self.text).map_err(|e| {
            let (line, column) = e
                .span()
                .map_or((0, 0), |span| line_column(self.text, span.start));
            ConfigError::Syntax {
                origin: self.origin.clone(),
                line,
                column,
                message: e.message().trim().to_string(),
            }
        })
    }

    /// The 1-based line on which the value of the dotted `key` (`"hull.mass_kg"`,
    /// `"thrusters.0.gain"`) starts, if the document has it.
    pub fn line_of(&self, key: &str) -> Option<usize> {
        let table = toml::de::DeTable::parse(self.text).ok()?;
        let mut span: Range<usize> = table.span();
        let mut value: Option<&toml::de::DeValue<'_>> = None;
        let mut current = table.get_ref();
        for part in key.split('.') {
            let next = match value {
                None => current.get(part),
                Some(toml::de::DeValue::Table(t)) => {
                    current = t;
                    current.get(part)
                }
                Some(toml::de::DeValue::Array(a)) => {
                    part.parse::<usize>().ok().and_then(|i| a.get(i))
                }
                Some(_) => None,
            }?;
            span = next.span();
            value = Some(next.get_ref());
        }
        Some(line_column(self.text, span.start).0)
    }

    /// An [`ConfigError::Invalid`] for `key`, pointing at its line.
    pub fn invalid(&self, key: &str, message: impl Into<String>) -> ConfigError {
        ConfigError::Invalid {
            origin: self.origin.clone(),
            key: key.to_string(),
            line: self.line_of(key),
            message: message.into(),
        }
    }

    /// Checks that a finite `value` lies in `[min, max]`; the error states the unit.
    pub fn check_range(
        &self,
        key: &str,
        value: f64,
        min: f64,
        max: f64,
        unit: &str,
    ) -> Result<f64, ConfigError> {
        if value.is_finite() && (min..=max).contains(&value) {
            Ok(value)
        } else {
            Err(self.invalid(
                key,
                // `{:?}` writes 1e308 as `1e308`, not as 309 digits.
                format!("{value:?} {unit} is outside the allowed range {min}..={max} {unit}"),
            ))
        }
    }
}

/// 1-based line and column of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.bytes().filter(|&b| b == b'\n').count() + 1;
    let column = before
        .rfind('\n')
        .map_or(before.len(), |nl| before.len() - nl - 1)
        + 1;
    (line, column)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device, a FIFO, a directory or an oversized file is an error naming what was found,
    /// read with bounded memory and without waiting for a FIFO's writer.
    #[test]
    fn config_files_are_read_bounded_and_without_blocking() {
        let err = read_config_file(Path::new("/dev/zero")).unwrap_err();
        assert!(err.contains("a device"), "{err}");
        let tmp = crate::scratch::dir("cfg-read");
        let fifo = tmp.path().join("fifo.toml");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let err = read_config_file(&fifo).unwrap_err();
        assert!(err.contains("a FIFO"), "{err}");
        let err = read_config_file(tmp.path()).unwrap_err();
        assert!(err.contains("a directory"), "{err}");
        let big = tmp.path().join("big.toml");
        std::fs::write(&big, vec![b'#'; MAX_CONFIG_BYTES as usize + 1]).unwrap();
        let err = read_config_file(&big).unwrap_err();
        assert!(err.contains("larger than"), "{err}");
        let ok = tmp.path().join("ok.toml");
        std::fs::write(&ok, "a = 1\n").unwrap();
        assert_eq!(read_config_file(&ok).unwrap(), "a = 1\n");
        let err = Directory::new(tmp.path()).read("fifo.toml").unwrap_err();
        assert!(
            err.to_string().contains("fifo.toml") && err.to_string().contains("FIFO"),
            "{err}"
        );
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Raw {
        hull: RawHull,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct RawHull {
        mass_kg: f64,
    }

    #[test]
    fn unknown_key_names_file_line_and_key() {
        let doc = Document::new("v.toml", "[hull]\nmass_kg = 35.0\nmas_kg = 1\n");
        let err = doc.parse::<Raw>().unwrap_err().to_string();
        assert!(err.starts_with("v.toml:3:"), "{err}");
        assert!(err.contains("mas_kg"), "{err}");
    }

    #[test]
    fn wrong_type_is_a_syntax_error_with_position() {
        let doc = Document::new("v.toml", "[hull]\nmass_kg = \"heavy\"\n");
        let err = doc.parse::<Raw>().unwrap_err();
        assert!(matches!(err, ConfigError::Syntax { line: 2, .. }), "{err}");
    }

    #[test]
    fn range_error_points_at_the_key_line() {
        let doc = Document::new("v.toml", "# comment\n[hull]\n\nmass_kg = -3.0\n");
        let err = doc
            .check_range("hull.mass_kg", -3.0, 1.0, 500.0, "kg")
            .unwrap_err();
        assert!(
            matches!(&err, ConfigError::Invalid { line: Some(4), .. }),
            "{err}"
        );
        assert!(err.to_string().contains("kg"));
        assert!(
            doc.check_range("hull.mass_kg", f64::NAN, 1.0, 500.0, "kg")
                .is_err()
        );
    }

    /// A range error writes a huge or tiny value as `1e308`, not as its 309 digits.
    #[test]
    fn range_errors_write_extreme_values_short() {
        let doc = Document::new("v.toml", "[hull]\nmass_kg = 1e308\n");
        for (value, shown) in [
            (1e308, "1e308 kg"),
            (1e-300, "1e-300 kg"),
            (-3.0, "-3.0 kg"),
        ] {
            let err = doc
                .check_range("hull.mass_kg", value, 1.0, 500.0, "kg")
                .unwrap_err()
                .to_string();
            assert!(err.contains(shown) && err.len() < 120, "{err}");
        }
    }

    #[test]
    fn line_of_follows_arrays_of_tables() {
        let doc = Document::new("v.toml", "[[thruster]]\ngain = 1\n[[thruster]]\ngain = 2\n");
        assert_eq!(doc.line_of("thruster.1.gain"), Some(4));
        assert_eq!(doc.line_of("thruster.2.gain"), None);
    }

    /// The embedded copies are exactly the files in `configs/`, so `run` without `--config`
    /// behaves like `run --config configs/default.toml`.
    #[test]
    fn embedded_configs_equal_the_files_on_disk() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
        let disk = Directory::new(&root);
        assert!(
            EMBEDDED_CONFIGS.iter().any(|(n, _)| *n == DEFAULT_CONFIG),
            "configs/{DEFAULT_CONFIG} is not embedded"
        );
        for (name, text) in EMBEDDED_CONFIGS {
            let on_disk = disk.read(name).expect("embedded file exists on disk");
            assert_eq!(
                on_disk.as_ref(),
                *text,
                "embedded {name} differs from configs/{name}"
            );
        }
    }

    /// A config comment says what a value is and why, like a code comment; where a number
    /// came from in the project's history belongs in git. No file under `configs/` cites a
    /// tracker entry or a work period as a value's reason.
    #[test]
    fn config_comments_cite_no_work_history() {
        fn walk(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
            for entry in std::fs::read_dir(dir).expect("list configs") {
                let path = entry.expect("a directory entry").path();
                if path.is_dir() {
                    walk(&path, out);
                } else {
                    out.push(path);
                }
            }
        }
        let mut files = Vec::new();
        walk(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("configs"),
            &mut files,
        );
        let mut citing = Vec::new();
        for file in files {
            let Ok(text) = std::fs::read_to_string(&file) else {
                continue;
            };
            for (n, line) in text.lines().enumerate() {
                let lower = line.to_lowercase();
                let cites = lower.match_indices("issue").any(|(at, _)| {
                    let rest = lower[at + "issue".len()..].trim_start_matches([' ', '#']);
                    rest.starts_with(|c: char| c.is_ascii_digit())
                });
                if cites || lower.contains("session") {
                    citing.push(format!("{}:{}: {line}", file.display(), n + 1));
                }
            }
        }
        assert!(citing.is_empty(), "{citing:#?}");
    }

    /// A configuration copied out of the clone finds its model files: read beside it when
    /// there, else the embedded copy of the same name; a file that is there but broken is
    /// an error; a name found in neither place is an error naming both places. (A copied
    /// `default.toml` failed with `: cannot read config`, naming no path.)
    #[test]
    fn files_a_configuration_names_are_read_beside_it_or_embedded() {
        let tmp = crate::scratch::dir("beside");
        let copy = tmp.path().join("default.toml");
        std::fs::write(&copy, Embedded.read(DEFAULT_CONFIG).unwrap().as_ref()).unwrap();
        let (source, name) = BesideOrEmbedded::for_file(&copy);
        assert_eq!(name, "default.toml");
        let embedded = Embedded.read("vehicles/mako.toml").unwrap();
        assert_eq!(source.read("vehicles/mako.toml").unwrap(), embedded);
        assert_eq!(
            source.describe("vehicles/mako.toml"),
            "<embedded>/vehicles/mako.toml"
        );

        std::fs::create_dir(tmp.path().join("vehicles")).unwrap();
        let mine = tmp.path().join("vehicles/mako.toml");
        std::fs::write(&mine, "# mine\n").unwrap();
        assert_eq!(source.read("vehicles/mako.toml").unwrap(), "# mine\n");
        assert_eq!(
            source.describe("vehicles/mako.toml"),
            mine.display().to_string()
        );
        std::fs::remove_file(&mine).unwrap();
        std::fs::create_dir(&mine).unwrap();
        let err = source.read("vehicles/mako.toml").unwrap_err().to_string();
        assert!(
            err.contains("a directory"),
            "not replaced by the embedded copy: {err}"
        );

        let err = source
            .read("vehicles/nowhere.toml")
            .unwrap_err()
            .to_string();
        let tried = tmp
            .path()
            .join("vehicles/nowhere.toml")
            .display()
            .to_string();
        assert!(
            err.contains(&tried) && err.contains("embedded `vehicles/nowhere.toml`"),
            "{err}"
        );
        assert!(!err.contains(": :"), "{err}");
    }

    /// A configuration named by its path in the clone is the embedded one when that path does
    /// not exist here (the README says the configs are embedded): `simulate
    /// configs/experiments/acceleration.toml` worked only inside the clone.
    #[test]
    fn a_missing_path_to_an_embedded_config_is_the_embedded_config() {
        let tmp = crate::scratch::dir("embedded-path");
        let path = tmp.path().join("configs/experiments/acceleration.toml");
        let (source, name) = BesideOrEmbedded::for_file(&path);
        assert_eq!(name, "experiments/acceleration.toml");
        assert_eq!(source.root(), None);
        assert_eq!(
            source.read(&name).unwrap(),
            Embedded.read("experiments/acceleration.toml").unwrap()
        );
        // A mistyped path is an error naming it, not the embedded file of that name.
        let typo = tmp.path().join("my/default.toml");
        let (source, name) = BesideOrEmbedded::for_file(&typo);
        let err = source.read(&name).unwrap_err().to_string();
        assert!(err.contains(&typo.display().to_string()), "{err}");
    }
}
