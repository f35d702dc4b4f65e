//! Progress reporting for long work, independent of how it is shown (a CLI progress bar, a GUI
//! bar, nothing in tests). Implementations must be cheap and thread-safe.

/// Receives progress from long-running library work.
pub trait Progress: Sync {
    /// A new stage begins with `total` units of work (0 when unknown).
    fn stage(&self, name: &str, total: u64);
    /// `units` more units of the current stage are done.
    fn advance(&self, units: u64);
    /// Whether the user asked to stop: long work checks it between (and inside) stages and
    /// returns its `Cancelled` error, leaving its inputs as they were.
    fn is_cancelled(&self) -> bool {
        false
    }
}

/// Discards progress.
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _name: &str, _total: u64) {}
    fn advance(&self, _units: u64) {}
}
