//! What `sdem bench` and `sdem bench --faults` both count over the pairs they localize: the
//! errors and times of each pair, and whether it succeeded.

use sdem_sim::benchmark::{success_rate, summarize, PairResult, Stats};

/// A localization within this of the truth is a success, metres.
pub(crate) const SUCCESS_M: f64 = 0.02;

/// The errors and times of the pairs a bench localized, in the order localized.
#[derive(Default)]
pub(crate) struct Tally {
    translation_mm: Vec<f64>,
    rotation_deg: Vec<f64>,
    times_ms: Vec<f64>,
}

impl Tally {
    /// Records one pair: its result, or `None` when the localization returned an error (which
    /// counts as infinitely wrong). Returns whether the pair failed (an error, or off by
    /// [`SUCCESS_M`] or more).
    pub(crate) fn record(&mut self, result: Option<&PairResult>) -> bool {
        match result {
            Some(r) => {
                self.translation_mm.push(r.translation_error_m * 1e3);
                self.rotation_deg.push(r.rotation_error_deg);
                self.times_ms.push(r.time_ms);
                r.translation_error_m >= SUCCESS_M
            }
            None => {
                self.translation_mm.push(f64::NAN);
                self.rotation_deg.push(f64::NAN);
                true
            }
        }
    }

    pub(crate) fn translation_error_mm(&self) -> Stats {
        summarize(&self.translation_mm)
    }

    pub(crate) fn rotation_error_deg(&self) -> Stats {
        summarize(&self.rotation_deg)
    }

    /// Times of the localizations that returned (errors have none).
    pub(crate) fn time_ms(&self) -> Stats {
        summarize(&self.times_ms)
    }

    pub(crate) fn success_rate(&self) -> f64 {
        let errors_m: Vec<f64> = self.translation_mm.iter().map(|e| e / 1e3).collect();
        success_rate(&errors_m, SUCCESS_M)
    }
}
