//! The thesis table (`eyebot-hil validate`, `cli::validate`): the thesis's measurements next
//! to SubSim's and ours.
//!
//! Each row is computed by running the simulator; nothing here is a stored answer. Physics
//! rows and sensor rows are produced by their own modules and share the [`Row`] shape, which
//! is also the JSON schema of `validate --json`.

pub mod sensors;

use serde::Serialize;

/// Which part of the model a row checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Group {
    Physics,
    Sensors,
}

/// A quantity: a number, or a qualitative outcome such as "turns right".
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Value {
    Number(f64),
    Text(String),
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Number(x) => {
                if x.abs() >= 100.0 || *x == x.round() {
                    write!(f, "{x:.1}")
                } else {
                    write!(f, "{x:.3}")
                }
            }
            Value::Text(s) => f.write_str(s),
        }
    }
}

/// One line of the validation table.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    pub quantity: String,
    /// Mako's value as the thesis reports it.
    pub measured: Value,
    /// SubSim 2.4's value where the thesis reports one.
    pub subsim: Option<Value>,
    /// What eyebot-hil computed, just now.
    pub simulated: Value,
    /// The acceptance band, in words (`"+-5 %"`, `"<= 9.5"`, `"95 % binomial interval"`).
    pub tolerance: String,
    pub unit: String,
    pub pass: bool,
    pub group: Group,
}

/// The rows as an aligned text table with the columns
/// quantity | Mako measured (thesis) | SubSim 2.4 (thesis) | eyebot-hil | tolerance | pass.
pub fn render_table(rows: &[Row]) -> String {
    let header = [
        "quantity",
        "Mako measured (thesis)",
        "SubSim 2.4 (thesis)",
        "eyebot-hil",
        "tolerance",
        "pass",
    ];
    let cells: Vec<[String; 6]> = rows
        .iter()
        .map(|r| {
            let with_unit = |v: &Value| match v {
                Value::Number(_) if !r.unit.is_empty() => format!("{v} {}", r.unit),
                _ => v.to_string(),
            };
            [
                r.quantity.clone(),
                with_unit(&r.measured),
                r.subsim.as_ref().map_or_else(|| "-".to_string(), with_unit),
                with_unit(&r.simulated),
                r.tolerance.clone(),
                if r.pass { "yes" } else { "NO" }.to_string(),
            ]
        })
        .collect();
    let mut widths = header.map(str::len);
    for row in &cells {
        for (w, c) in widths.iter_mut().zip(row) {
            *w = (*w).max(c.chars().count());
        }
    }
    let line = |cols: &[String]| {
        let mut s = String::from("|");
        for (c, w) in cols.iter().zip(widths) {
            s.push_str(&format!(" {c:<w$} |"));
        }
        s.push('\n');
        s
    };
    let mut out = line(&header.map(String::from));
    out.push('|');
    for w in widths {
        out.push_str(&format!("{}|", "-".repeat(w + 2)));
    }
    out.push('\n');
    for row in &cells {
        out.push_str(&line(row));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(pass: bool) -> Row {
        Row {
            quantity: "top surge speed at 100 %".into(),
            measured: Value::Number(0.44),
            subsim: Some(Value::Number(0.09)),
            simulated: Value::Number(0.4412),
            tolerance: "+-5 %".into(),
            unit: "m/s".into(),
            pass,
            group: Group::Physics,
        }
    }

    #[test]
    fn json_has_the_documented_fields() {
        let json = serde_json::to_value(vec![row(true)]).unwrap();
        let obj = json[0].as_object().unwrap();
        for key in [
            "quantity",
            "measured",
            "subsim",
            "simulated",
            "tolerance",
            "unit",
            "pass",
            "group",
        ] {
            assert!(obj.contains_key(key), "missing {key}");
        }
        assert_eq!(obj["group"], "physics");
        assert_eq!(obj["measured"], 0.44);
    }

    #[test]
    fn table_marks_failures() {
        let table = render_table(&[row(true), row(false)]);
        assert_eq!(table.lines().count(), 4);
        assert!(table.lines().nth(3).unwrap().contains("NO"));
        assert!(table.contains("0.440 m/s"));
    }
}

pub mod physics;

/// What every row source gets: where the configuration files come from and the seed.
/// `eyebot-hil validate` calls each source in [`crate::cli::validate`]'s list with it.
pub struct Context<'a> {
    /// The configs: the embedded copies, or a directory given by the user.
    pub configs: &'a dyn crate::config::ConfigSource,
    /// Seed of every RNG stream used by the runs.
    pub seed: u64,
}

/// Why a row source could not produce its rows (a failed check is a row with `pass: false`,
/// not an error).
#[derive(Debug, thiserror::Error)]
pub enum ValidateError {
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("experiment `{experiment}`: {source}")]
    Physics {
        experiment: String,
        source: crate::physics::PhysicsError,
    },
    #[error("experiment `{experiment}`: cannot measure {what}")]
    Measurement {
        experiment: String,
        what: &'static str,
    },
}
