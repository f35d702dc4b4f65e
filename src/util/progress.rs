//! Progress reporting for long work, independent of how it is shown (a CLI progress bar, a GUI
//! bar, nothing in tests). Implementations must be cheap and thread-safe.

/// Receives progress from long-running library work.
pub trait Progress: Sync {
    /// A new stage begins with `total` units of work (0 when unknown).
    fn stage(&self, name: &str, total: u64);
    /// `units` more units of the current stage are done.
    fn advance(&self, units: u64);
}

/// Discards progress.
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _name: &str, _total: u64) {}
    fn advance(&self, _units: u64) {}
}
