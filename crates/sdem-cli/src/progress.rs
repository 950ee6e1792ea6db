//! Progress bars on stderr for long work (simulate, slam, bench, view), quiet where they would
//! only clutter: when `--json` is given, or when stderr or stdout is not a terminal (a log file,
//! a pipe, a test harness).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;

/// A progress bar over `len` steps labelled `what` (e.g. `"scans"`), drawn on stderr; hidden
/// (every call on it a no-op) with `json` or when stderr or stdout is not a terminal.
///
/// Call `inc(1)` per step and `finish_and_clear()` at the end; print other lines with
/// `bar.suspend(|| eprintln!(…))` so they do not tear the bar.
pub fn bar(len: u64, json: bool, what: &str) -> ProgressBar {
    if json || !std::io::stderr().is_terminal() || !std::io::stdout().is_terminal() {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    let style = ProgressStyle::with_template(
        "{msg:>10} [{bar:40.cyan/blue}] {pos}/{len}  {elapsed_precise} elapsed, ~{eta} left",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("=> ");
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

#[cfg(test)]
mod tests {
    #[test]
    fn hidden_with_json() {
        let bar = super::bar(10, true, "scans");
        assert!(bar.is_hidden());
        bar.inc(1);
        bar.finish_and_clear();
    }
}
