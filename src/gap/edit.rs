//! Edits of the vehicle, sensor and world files: how a truth source that runs the real
//! configuration files (the bridge) hides an effect, key by key, in the library effect's own
//! parameters.

/// Which configuration file an edit changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum File {
    Vehicle,
    Sensors,
    World,
}

impl File {
    /// The embedded file the bridge's copy starts from.
    pub fn embedded(self) -> &'static str {
        match self {
            File::Vehicle => "vehicles/mako.toml",
            File::Sensors => "sensors/mako-2008.toml",
            File::World => "worlds/pool.toml",
        }
    }

    /// The name of the edited copy in a run directory.
    pub fn file_name(self) -> &'static str {
        match self {
            File::Vehicle => "vehicle.toml",
            File::Sensors => "sensors.toml",
            File::World => "world.toml",
        }
    }
}

/// How an edit changes a number (a missing key counts as 0, or is created by `Set`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Change {
    Set(f64),
    Scale(f64),
    Add(f64),
}

/// One edit of a configuration file: `key` is a dotted path with `[i]` indices
/// (`damping.linear[5]`, `thruster[1].gain`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edit {
    pub file: File,
    pub key: &'static str,
    pub change: Change,
}

/// An edit of `file`'s `key`.
pub const fn edit(file: File, key: &'static str, change: Change) -> Edit {
    Edit { file, key, change }
}
