//! `eyebot-hil validate [--json] [--configs DIR] [--seed N]`: the thesis's measurements next to
//! SubSim's and ours. Rows come from the sources in [`ROW_SOURCES`]; each computes its rows by
//! running the simulator now.

use std::path::PathBuf;

use crate::cli::CliError;
use crate::cli::output::{out, outln};
use crate::config::{BesideOrEmbedded, ConfigSource, Directory, Embedded};
use crate::thesis::{Context, Row, ValidateError, render_table};

/// A producer of validation rows.
pub type RowSource = fn(&Context<'_>) -> Result<Vec<Row>, ValidateError>;

/// Every row source, in table order.
pub const ROW_SOURCES: &[RowSource] = &[
    crate::thesis::physics::rows,
    crate::thesis::sensors::row_source,
];

/// Arguments of `validate`.
#[derive(Debug, Clone, clap::Args)]
pub struct ValidateArgs {
    /// Print one JSON array of rows instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Read configs from this directory instead of the embedded copies of configs/.
    #[arg(long)]
    pub configs: Option<PathBuf>,
    /// Seed of every RNG stream.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// All rows from all sources.
pub fn collect(ctx: &Context<'_>) -> Result<Vec<Row>, ValidateError> {
    let mut rows = Vec::new();
    for source in ROW_SOURCES {
        rows.extend(source(ctx)?);
    }
    Ok(rows)
}

pub fn run(args: &ValidateArgs) -> Result<(), CliError> {
    let dir;
    let configs: &dyn ConfigSource = match &args.configs {
        Some(path) => {
            dir = BesideOrEmbedded::new(Directory::new(path));
            &dir
        }
        None => &Embedded,
    };
    let rows = collect(&Context {
        configs,
        seed: args.seed,
    })?;
    if args.json {
        let json =
            serde_json::to_string_pretty(&rows).map_err(|e| CliError::Output(e.to_string()))?;
        outln!("{json}");
    } else {
        out!("{}", render_table(&rows));
    }
    let failed = rows.iter().filter(|r| !r.pass).count();
    if failed > 0 {
        return Err(CliError::ValidationFailed {
            failed,
            total: rows.len(),
        });
    }
    Ok(())
}
