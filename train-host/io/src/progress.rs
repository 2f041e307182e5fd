//! Progress on standard error for anything that can take longer than a
//! second (issue 10, items 5 and 15): reading and reducing large clouds,
//! registering, scoring a pair set, a training epoch.
//!
//! A [`Progress`] stays invisible for its first second, so quick jobs print
//! nothing; after that it shows a bar with a rate and an estimate of the
//! time left (or a spinner with the elapsed time when the amount of work
//! is not known). It draws only when standard error is a terminal
//! (`indicatif`'s rule), and clears itself when dropped. Results are never
//! printed through it: logs and pipes see the same lines either way.

use std::sync::mpsc;
use std::thread::JoinHandle;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// How long a job runs before its progress appears.
pub const SHOW_AFTER: Duration = Duration::from_secs(1);

/// A progress bar or spinner that appears after [`SHOW_AFTER`]; see the
/// module docs.
pub struct Progress {
    bar: ProgressBar,
    done: Option<mpsc::Sender<()>>,
    shower: Option<JoinHandle<()>>,
}

impl Progress {
    /// A bar over `len` units of work, labelled `message`.
    pub fn bar(len: u64, message: impl Into<String>) -> Progress {
        Progress::start(
            ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden()),
            "{msg} [{bar:30}] {pos}/{len} {per_sec} eta {eta}",
            message.into(),
        )
    }

    /// A spinner with the elapsed time, labelled `message`.
    pub fn spinner(message: impl Into<String>) -> Progress {
        Progress::start(
            ProgressBar::with_draw_target(None, ProgressDrawTarget::hidden()),
            "{spinner} {msg} ({elapsed})",
            message.into(),
        )
    }

    fn start(bar: ProgressBar, template: &str, message: String) -> Progress {
        let style = ProgressStyle::with_template(template)
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> ");
        bar.set_style(style);
        bar.set_message(message);
        bar.enable_steady_tick(Duration::from_millis(200));
        let (done, wait) = mpsc::channel::<()>();
        let shown = bar.clone();
        let shower = std::thread::spawn(move || {
            // Shown only if nobody said "done" (or dropped the sender)
            // within the first second.
            if let Err(mpsc::RecvTimeoutError::Timeout) = wait.recv_timeout(SHOW_AFTER) {
                shown.set_draw_target(ProgressDrawTarget::stderr());
            }
        });
        Progress {
            bar,
            done: Some(done),
            shower: Some(shower),
        }
    }

    /// `n` more units done (safe from several threads through `&self`).
    pub fn inc(&self, n: u64) {
        self.bar.inc(n);
    }

    /// Replaces the label.
    pub fn set_message(&self, message: impl Into<String>) {
        self.bar.set_message(message.into());
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if let Some(done) = self.done.take() {
            // The shower may have gone already: nothing to tell it then.
            let _ = done.send(());
        }
        if let Some(shower) = self.shower.take() {
            let _ = shower.join();
        }
        self.bar.finish_and_clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quick_job_never_shows_and_drops_cleanly() {
        let p = Progress::bar(10, "quick");
        for _ in 0..10 {
            p.inc(1);
        }
        assert!(p.bar.is_hidden());
        drop(p);
        let s = Progress::spinner("quick");
        assert!(s.bar.is_hidden());
    }
}
