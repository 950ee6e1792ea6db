//! Parsing of the command line's numbers: comma-separated lists, and clap's value parsers, whose
//! refusals are usage errors (exit status 2; clap's message names the flag and the value, so
//! theirs says only what the value must be).

/// Parses `N` comma-separated finite numbers; `form` names them in the message (which does not
/// name the flag: clap's, or the caller's, does).
pub fn numbers<const N: usize>(text: &str, form: &str) -> Result<[f64; N], String> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| format!("expected {N} finite numbers {form}"))?;
    let count = values.len();
    values
        .try_into()
        .map_err(|_| format!("expected {N} numbers {form}, got {count}"))
}

/// A clap value parser: a positive, finite number of metres.
pub fn positive_metres(text: &str) -> Result<f64, String> {
    positive(text).ok_or_else(|| "must be a positive number of metres (> 0)".into())
}

/// A clap value parser: a positive, finite number of degrees.
pub fn positive_degrees(text: &str) -> Result<f64, String> {
    positive(text).ok_or_else(|| "must be a positive number of degrees (> 0)".into())
}

/// `text` as a finite number > 0.
fn positive(text: &str) -> Option<f64> {
    (text.trim().parse::<f64>().ok()).filter(|v| v.is_finite() && *v > 0.0)
}

/// A usage error of `sdem SUBCOMMAND` found after parsing (options that do not fit together),
/// as clap reports its own: `main` prints it with the subcommand's usage and exits with status 2.
pub fn usage_error(subcommand: &str, message: impl std::fmt::Display) -> anyhow::Error {
    use clap::CommandFactory;
    let mut cli = crate::Cli::command();
    cli.build();
    let kind = clap::error::ErrorKind::ArgumentConflict;
    let error = match cli.find_subcommand_mut(subcommand) {
        Some(command) => command.error(kind, message),
        None => cli.error(kind, message),
    };
    anyhow::Error::new(error)
}

/// A number for a message: as `{}` for ordinary magnitudes, with an exponent (`1e9`) from 1e6
/// up and below 1e-4, so that a value typed as `1e9` reads back as typed.
pub fn fmt_number(value: f64) -> String {
    let magnitude = value.abs();
    if value == 0.0 || (1e-4..1e6).contains(&magnitude) || !value.is_finite() {
        format!("{value}")
    } else {
        format!("{value:e}")
    }
}
