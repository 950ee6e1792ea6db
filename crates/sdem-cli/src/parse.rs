//! Parsing of the command line's numbers: comma-separated lists, numbers and counts within a
//! range, and clap's value parsers built on them, whose refusals are usage errors (exit status 2;
//! clap's message names the flag and the value, so theirs says only what the value must be);
//! and [`usage_error`] for values that are each fine but do not fit together.

use std::ops::{Bound, RangeBounds, RangeInclusive};

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

/// `text` as a finite number within `range`; else the message says it must be `what` (which
/// names the range, and why where it helps). The core of the number parsers below, and of the
/// commands' own for ranges of their own.
pub fn number_in(text: &str, range: impl RangeBounds<f64>, what: &str) -> Result<f64, String> {
    (text.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite() && range.contains(v))
        .ok_or_else(|| format!("must be {what}"))
}

/// `text` as a whole number within `range`; else the message says it must be one, with the
/// range (`1..=40`, or `≥ 1` when unbounded above) and `why`, when not empty, after a colon.
pub fn count_in(text: &str, range: RangeInclusive<usize>, why: &str) -> Result<usize, String> {
    (text.trim().parse::<usize>().ok())
        .filter(|n| range.contains(n))
        .ok_or_else(|| {
            let (low, high) = (range.start(), range.end());
            let range = match *high {
                usize::MAX => format!("≥ {low}"),
                _ => format!("in {low}..={high}"),
            };
            match why {
                "" => format!("must be a whole number {range}"),
                why => format!("must be a whole number {range}: {why}"),
            }
        })
}

/// The range of the positive numbers, for [`number_in`].
pub const POSITIVE: (Bound<f64>, Bound<f64>) = (Bound::Excluded(0.0), Bound::Unbounded);

/// A clap value parser: a positive, finite number of metres.
pub fn positive_metres(text: &str) -> Result<f64, String> {
    number_in(text, POSITIVE, "a positive number of metres (> 0)")
}

/// A clap value parser: a positive, finite number of degrees.
pub fn positive_degrees(text: &str) -> Result<f64, String> {
    number_in(text, POSITIVE, "a positive number of degrees (> 0)")
}

/// A clap value parser: a positive, finite number of seconds.
pub fn positive_seconds(text: &str) -> Result<f64, String> {
    number_in(text, POSITIVE, "a positive number of seconds (> 0)")
}

/// A clap value parser: a finite number of degrees ≥ 0 (a standard deviation, a noise).
pub fn non_negative_degrees(text: &str) -> Result<f64, String> {
    number_in(text, 0.0.., "a finite number of degrees ≥ 0")
}

/// A clap value parser: a whole number ≥ 1.
pub fn positive_count(text: &str) -> Result<usize, String> {
    count_in(text, 1..=usize::MAX, "")
}

/// A clap value parser: a heading window, ± degrees around the compass readings' difference.
pub fn heading_window_degrees(text: &str) -> Result<f64, String> {
    number_in(
        text,
        0.0..=180.0,
        "in [0, 180] degrees (0 trusts the compass, 180 searches a full turn)",
    )
}

/// A clap value parser: an S-DEM cell size, degrees, checked as the S-DEM grid checks it.
pub fn resolution_degrees(text: &str) -> Result<f64, String> {
    let resolution_deg = (text.trim().parse::<f64>())
        .map_err(|_| "must be a number of degrees in (0, 45], the S-DEM's cell size".to_string())?;
    let grid = sdem::sdem::SdemConfig {
        resolution_deg,
        ..Default::default()
    };
    grid.validate().map_err(|e| e.to_string())?;
    Ok(resolution_deg)
}

/// A usage error of `sdem SUBCOMMAND` found after parsing (options that do not fit together),
/// as clap reports its own: `main` prints it with the subcommand's usage and exits with status 2.
/// `subcommand` may name a nested one: `"view cost"`.
pub fn usage_error(subcommand: &str, message: impl std::fmt::Display) -> anyhow::Error {
    use clap::CommandFactory;
    let mut cli = crate::Cli::command();
    cli.build();
    let mut command = &mut cli;
    for name in subcommand.split_whitespace() {
        if command.find_subcommand(name).is_none() {
            break;
        }
        command = command.find_subcommand_mut(name).expect("found above");
    }
    let kind = clap::error::ErrorKind::ArgumentConflict;
    anyhow::Error::new(command.error(kind, message))
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_count_out_of_its_range_or_malformed_is_refused_with_the_range_and_why() {
        assert_eq!(count_in("40", 2..=40, ""), Ok(40));
        assert_eq!(count_in(" 2 ", 2..=40, ""), Ok(2));
        for text in ["1", "41", "-2", "x", "2.5", ""] {
            assert_eq!(
                count_in(text, 2..=40, "the route holds 40"),
                Err("must be a whole number in 2..=40: the route holds 40".to_string()),
                "{text:?}"
            );
        }
        assert_eq!(
            positive_count("0"),
            Err("must be a whole number ≥ 1".to_string())
        );
        assert_eq!(positive_count("7"), Ok(7));
    }

    #[test]
    fn a_number_outside_its_range_or_not_finite_is_refused() {
        assert_eq!(number_in("0", 0.0..8.0, "x"), Ok(0.0));
        assert_eq!(positive_metres("0.01"), Ok(0.01));
        for text in ["0", "-1", "nan", "inf", "-inf", "1e999", "metre"] {
            assert!(positive_metres(text).is_err(), "{text:?}");
        }
        assert_eq!(
            number_in("8", 0.0..8.0, "in [0, 8)"),
            Err("must be in [0, 8)".to_string())
        );
        assert!(non_negative_degrees("-0.1").is_err());
        assert_eq!(heading_window_degrees("180"), Ok(180.0));
        assert!(heading_window_degrees("180.5").is_err());
        assert!(resolution_degrees("46").is_err() && resolution_degrees("45").is_ok());
    }
}
