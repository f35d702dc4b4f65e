//! Long work off the UI thread: a worker thread, its progress (stage, fraction) for the
//! progress bar, and cooperative cancellation through the library's `Progress` trait.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, channel};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

use frond::util::progress::Progress;

/// Progress shared between a worker and the UI.
#[derive(Default)]
pub struct JobProgress {
    stage: Mutex<String>,
    total: AtomicU64,
    done: AtomicU64,
    cancelled: AtomicBool,
}

impl Progress for JobProgress {
    fn stage(&self, name: &str, total: u64) {
        *self.stage.lock().unwrap_or_else(|e| e.into_inner()) = name.to_owned();
        self.done.store(0, Ordering::Relaxed);
        self.total.store(total, Ordering::Relaxed);
    }

    fn advance(&self, units: u64) {
        self.done.fetch_add(units, Ordering::Relaxed);
    }

    fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
}

impl JobProgress {
    /// The current stage and its completed fraction (`None` when the stage has no total).
    pub fn snapshot(&self) -> (String, Option<f32>) {
        let stage = self.stage.lock().unwrap_or_else(|e| e.into_inner()).clone();
        let total = self.total.load(Ordering::Relaxed);
        let done = self.done.load(Ordering::Relaxed);
        let fraction = (total > 0).then(|| (done.min(total) as f32) / total as f32);
        (stage, fraction)
    }

    /// Asks the worker to stop at its next check.
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }
}

/// Holds new workers before they start until it is opened or their job is cancelled, so a
/// script (a test, a recorded demo) can act on a job that is certainly still running.
#[derive(Default)]
pub struct StartGate {
    open: Mutex<bool>,
    changed: Condvar,
}

impl StartGate {
    /// Lets every held and every later worker start.
    pub fn open(&self) {
        *self.open.lock().unwrap_or_else(|e| e.into_inner()) = true;
        self.changed.notify_all();
    }

    /// Whether workers may start.
    pub fn is_open(&self) -> bool {
        *self.open.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Waits until the gate opens or `progress` is cancelled (a cancelled worker starts and
    /// stops at its first check).
    fn wait(&self, progress: &JobProgress) {
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        while !*open && !progress.is_cancelled() {
            // Cancellation is a flag, not a notification: look at it again every few ms.
            open = self
                .changed
                .wait_timeout(open, std::time::Duration::from_millis(5))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

/// What polling a job gives.
pub enum Poll<T> {
    Running,
    Done(T),
    /// The worker ended without a result (it panicked).
    Lost,
}

/// A running piece of work and where its result arrives.
pub struct Job<T> {
    pub title: String,
    pub progress: Arc<JobProgress>,
    pub started: Instant,
    result: Receiver<T>,
}

impl<T: Send + 'static> Job<T> {
    /// Starts `work` on a new thread.
    pub fn spawn(
        title: impl Into<String>,
        work: impl FnOnce(&JobProgress) -> T + Send + 'static,
    ) -> Self {
        Self::spawn_gated(title, None, work)
    }

    /// Starts `work` on a new thread that first waits at `gate` (when given).
    pub fn spawn_gated(
        title: impl Into<String>,
        gate: Option<Arc<StartGate>>,
        work: impl FnOnce(&JobProgress) -> T + Send + 'static,
    ) -> Self {
        let progress = Arc::new(JobProgress::default());
        let (sender, receiver) = channel();
        let worker_progress = Arc::clone(&progress);
        std::thread::spawn(move || {
            if let Some(gate) = gate {
                gate.wait(&worker_progress);
            }
            let result = work(&worker_progress);
            // The UI may have gone; nothing to do then.
            let _ = sender.send(result);
        });
        Self {
            title: title.into(),
            progress,
            started: Instant::now(),
            result: receiver,
        }
    }

    /// The result, once the worker has finished.
    pub fn poll(&self) -> Poll<T> {
        match self.result.try_recv() {
            Ok(result) => Poll::Done(result),
            Err(TryRecvError::Empty) => Poll::Running,
            Err(TryRecvError::Disconnected) => Poll::Lost,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_reports_stage_fraction_and_cancellation() {
        let progress = JobProgress::default();
        progress.stage("fitting", 4);
        progress.advance(1);
        assert_eq!(progress.snapshot(), ("fitting".to_owned(), Some(0.25)));
        progress.advance(10);
        assert_eq!(progress.snapshot().1, Some(1.0));
        progress.stage("export", 0);
        assert_eq!(progress.snapshot(), ("export".to_owned(), None));
        assert!(!progress.is_cancelled());
        progress.cancel();
        assert!(progress.is_cancelled());
    }

    #[test]
    fn a_job_delivers_its_result_and_sees_cancellation() {
        let job = Job::spawn("wait", |progress: &JobProgress| {
            while !progress.is_cancelled() {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            42
        });
        assert!(matches!(job.poll(), Poll::Running));
        job.progress.cancel();
        let value = loop {
            match job.poll() {
                Poll::Done(v) => break v,
                Poll::Running => std::thread::sleep(std::time::Duration::from_millis(1)),
                Poll::Lost => panic!("worker lost"),
            }
        };
        assert_eq!(value, 42);
    }

    fn wait_for<T: Send + 'static>(job: &Job<T>) -> T {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        loop {
            match job.poll() {
                Poll::Done(v) => return v,
                Poll::Running => {
                    assert!(
                        std::time::Instant::now() < deadline,
                        "worker never finished"
                    );
                    std::thread::sleep(std::time::Duration::from_millis(1));
                }
                Poll::Lost => panic!("worker lost"),
            }
        }
    }

    #[test]
    fn a_closed_gate_holds_workers_until_opened_or_cancelled() {
        let gate = Arc::new(StartGate::default());
        let started = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&started);
        let held = Job::spawn_gated("held", Some(Arc::clone(&gate)), move |progress| {
            flag.store(true, Ordering::SeqCst);
            progress.is_cancelled()
        });
        std::thread::sleep(std::time::Duration::from_millis(50));
        assert!(
            !started.load(Ordering::SeqCst),
            "started through a closed gate"
        );
        assert!(matches!(held.poll(), Poll::Running));
        // Cancelled while held: the worker starts and sees the cancellation.
        held.progress.cancel();
        assert!(wait_for(&held));
        assert!(started.load(Ordering::SeqCst));

        let next = Job::spawn_gated("next", Some(Arc::clone(&gate)), |progress| {
            progress.is_cancelled()
        });
        assert!(!gate.is_open());
        gate.open();
        assert!(!wait_for(&next));
        // An open gate lets later workers straight through.
        let later = Job::spawn_gated("later", Some(gate), |_| 7);
        assert_eq!(wait_for(&later), 7);
    }
}
