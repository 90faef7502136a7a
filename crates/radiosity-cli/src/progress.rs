//! Progress bars on stderr (indicatif) and the Ctrl-C stop flag.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use radiosity::Progress;

/// Set by the first Ctrl-C; the library polls it and stops with what it has.
pub static STOP: AtomicBool = AtomicBool::new(false);

/// Installs the Ctrl-C handler: first press asks the work to stop (outputs are still
/// written), a second press exits at once.
pub fn install_ctrlc() {
    let _ = ctrlc::set_handler(|| {
        if STOP.swap(true, Ordering::SeqCst) {
            eprintln!("\ninterrupted twice: exiting without writing outputs");
            std::process::exit(130);
        }
        eprintln!("\ninterrupt: stopping and writing the result so far (Ctrl-C again to abort)");
    });
}

/// True once Ctrl-C was pressed.
pub fn stopped() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// How often a long stage logs its progress when stderr is no terminal.
const LOG_EVERY: Duration = Duration::from_secs(30);

/// The progress line a long stage logs without a terminal: where it is, the time so far
/// and, once something is done, the time left at the rate so far.
fn log_line(stage: &str, pos: u64, total: u64, seconds: f64) -> String {
    let mut line = format!("{stage}: {pos}/{total}");
    if total > 0 {
        line += &format!(" ({:.0} %)", 100.0 * pos as f64 / total as f64);
    }
    line += &format!(", {seconds:.0} s");
    if pos > 0 && total > pos {
        line += &format!(", about {:.0} s left", seconds * (total - pos) as f64 / pos as f64);
    }
    line
}

/// Progress bars on stderr; silent when `quiet` or stderr is not a terminal (messages
/// still print unless quiet; a long stage then logs a line every 30 s).
pub struct CliProgress {
    bar: Mutex<Option<ProgressBar>>,
    /// The current stage and when it began (for the log line when stderr is no terminal).
    stage: Mutex<Option<(String, std::time::Instant)>>,
    /// Every finished stage with its seconds, for the report.
    done: Mutex<Vec<radiosity::report::StageTime>>,
    /// When the last progress line of the current stage was logged (no terminal only).
    logged: Mutex<std::time::Instant>,
    quiet: bool,
    log: bool,
}

impl CliProgress {
    /// A reporter.
    pub fn new(quiet: bool) -> Self {
        use std::io::IsTerminal;
        CliProgress {
            bar: Mutex::new(None),
            stage: Mutex::new(None),
            done: Mutex::new(Vec::new()),
            logged: Mutex::new(std::time::Instant::now()),
            quiet,
            log: !std::io::stderr().is_terminal(),
        }
    }

    /// The stages finished so far with their seconds (for `Timings::stages`).
    pub fn stages(&self) -> Vec<radiosity::report::StageTime> {
        self.done.lock().unwrap().clone()
    }
}

impl Progress for CliProgress {
    fn begin(&self, stage: &str, total: u64) {
        *self.stage.lock().unwrap() = Some((stage.to_string(), std::time::Instant::now()));
        *self.logged.lock().unwrap() = std::time::Instant::now();
        if self.quiet {
            return;
        }
        let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
        bar.set_style(
            ProgressStyle::with_template("{msg:>14} [{bar:40}] {pos}/{len} {elapsed_precise} (eta {eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        bar.set_message(stage.to_string());
        bar.enable_steady_tick(Duration::from_millis(200));
        *self.bar.lock().unwrap() = Some(bar);
    }
    fn advance(&self, n: u64) {
        if let Some(b) = self.bar.lock().unwrap().as_ref() {
            b.inc(n);
            // Without a terminal the bar is hidden: a long stage logs where it is every
            // LOG_EVERY, so a log (CI, nohup, a pipe) shows that the work goes on.
            if self.log {
                let mut last = self.logged.lock().unwrap();
                if last.elapsed() >= LOG_EVERY {
                    *last = std::time::Instant::now();
                    if let Some((stage, t)) = self.stage.lock().unwrap().as_ref() {
                        eprintln!("{}", log_line(stage, b.position(), b.length().unwrap_or(0), t.elapsed().as_secs_f64()));
                    }
                }
            }
        }
    }
    fn end(&self) {
        if let Some(b) = self.bar.lock().unwrap().take() {
            b.finish_and_clear();
        }
        // Without a terminal the bars are hidden: a log (CI, nohup) still gets one line per
        // stage that took a while.
        if let Some((stage, t)) = self.stage.lock().unwrap().take() {
            let s = t.elapsed().as_secs_f64();
            if self.log && !self.quiet && s >= 1.0 {
                eprintln!("{stage}: {s:.1} s");
            }
            self.done.lock().unwrap().push(radiosity::report::StageTime { stage, seconds: s });
        }
    }
    fn message(&self, msg: &str) {
        if self.quiet {
            return;
        }
        match self.bar.lock().unwrap().as_ref() {
            Some(b) => b.println(msg),
            None => eprintln!("{msg}"),
        }
    }
    /// Warnings print under `--quiet` too (the flag's promise: no progress, but errors and
    /// warnings).
    fn warning(&self, msg: &str) {
        let msg = format!("warning: {msg}");
        match self.bar.lock().unwrap().as_ref() {
            Some(b) => b.println(msg),
            None => eprintln!("{msg}"),
        }
    }
    fn should_stop(&self) -> bool {
        stopped()
    }
}

#[cfg(test)]
mod tests {
    use super::log_line;

    #[test]
    fn a_long_stage_logs_its_position_and_the_time_left() {
        assert_eq!(log_line("form factors", 25, 100, 30.0), "form factors: 25/100 (25 %), 30 s, about 90 s left");
        // Nothing done yet: no estimate; done: none left to estimate.
        assert_eq!(log_line("links", 0, 10, 31.0), "links: 0/10 (0 %), 31 s");
        assert_eq!(log_line("links", 10, 10, 40.0), "links: 10/10 (100 %), 40 s");
    }
}
