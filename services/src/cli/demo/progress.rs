//! The demo's terminal: an upload bar and a fit bar (indicatif), the fit bar moved by the
//! workers' [`OnJob`] callback, and the log lines (the served requests) written above the bars
//! rather than through them.

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use indicatif::{MultiProgress, ProgressBar, ProgressStyle};

use crate::worker::{JobEvent, OnJob};

fn style(template: &str) -> ProgressStyle {
    ProgressStyle::with_template(template).unwrap_or_else(|_| ProgressStyle::default_bar())
}

/// The fleet's upload and fit bars (drawn only on a terminal).
pub struct Progress {
    pub upload: ProgressBar,
    pub fit: ProgressBar,
    failed: Arc<AtomicUsize>,
}

impl Progress {
    /// Both bars, `tests` long, added to `bars`.
    pub fn new(bars: &MultiProgress, tests: usize) -> Progress {
        let upload = bars.add(ProgressBar::new(tests as u64));
        upload.set_style(style(
            "{prefix:>9} [{bar:40}] {pos}/{len} {per_sec:>10} {elapsed}",
        ));
        upload.set_prefix("upload");
        let fit = bars.add(ProgressBar::new(tests as u64));
        fit.set_style(style(
            "{prefix:>9} [{bar:40}] {pos}/{len} {per_sec:>10} {elapsed} {msg}",
        ));
        fit.set_prefix("fit");
        Progress {
            upload,
            fit,
            failed: Arc::new(AtomicUsize::new(0)),
        }
    }

    /// Jobs that failed so far.
    pub fn failed(&self) -> usize {
        self.failed.load(Ordering::Relaxed)
    }

    /// The workers' callback: every job done or failed moves the fit bar, until the bar is
    /// finished (the fleet fitted; later uploads of the served API do not redraw it).
    pub fn on_job(&self) -> OnJob {
        let (bar, failed) = (self.fit.clone(), self.failed.clone());
        Arc::new(move |ev: &JobEvent| {
            if bar.is_finished() {
                return;
            }
            match ev {
                JobEvent::Failed { .. } => {
                    let n = failed.fetch_add(1, Ordering::Relaxed) + 1;
                    bar.set_message(format!("{n} failed"));
                }
                JobEvent::LeaseLost { .. } | JobEvent::Released { .. } => return,
                JobEvent::Done { .. } => {}
            }
            bar.inc(1);
        })
    }
}

/// Logging as `init_logging` installs it (text, `RUST_LOG` or `filter`), each line written
/// above the bars of `bars` (they are suspended while it is written).
pub fn init_logging_above(bars: &MultiProgress, filter: &str) {
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .or_else(|_| tracing_subscriber::EnvFilter::try_new(filter))
        .unwrap_or_else(|_| "info".into());
    let bars = bars.clone();
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(move || AboveBars {
            bars: bars.clone(),
            line: Vec::new(),
        })
        .try_init();
}

/// One log event, collected and written to stderr at once with the bars suspended.
struct AboveBars {
    bars: MultiProgress,
    line: Vec<u8>,
}

impl Write for AboveBars {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.line.extend_from_slice(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for AboveBars {
    fn drop(&mut self) {
        if self.line.is_empty() {
            return;
        }
        let line = std::mem::take(&mut self.line);
        self.bars.suspend(|| {
            let _ = std::io::stderr().write_all(&line);
        });
    }
}
