//! Parsing of the command line's comma-separated number lists.

use anyhow::{Context, Result};

/// Parses `N` comma-separated finite numbers given to `flag`; `form` names them in messages.
pub fn parse_numbers<const N: usize>(flag: &str, text: &str, form: &str) -> Result<[f64; N]> {
    let values: Vec<f64> = text
        .split(',')
        .map(|v| v.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .with_context(|| format!("{flag} '{text}': expected {N} finite numbers {form}"))?;
    let count = values.len();
    values
        .try_into()
        .map_err(|_| anyhow::anyhow!("{flag} '{text}': expected {N} numbers {form}, got {count}"))
}
