//! One module per command.

pub mod bench;
pub mod calibrate;
pub mod classify;
pub mod config;
pub mod demo;
pub mod eval;
pub mod inspect;
pub mod synth;
pub mod track;
pub mod train;

/// A usage error found by a command after parsing (exit code 2).
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}

/// A progress bar on stderr when it is a terminal, else nothing.
pub fn progress_bar(len: u64, message: &str) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = indicatif::ProgressBar::new(len);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} {elapsed}")
    {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message(message.to_string());
    Some(bar)
}

/// A frame progress bar with frames/s on stderr when it is a terminal, else nothing.
pub fn frame_bar(len: Option<usize>) -> Option<indicatif::ProgressBar> {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let bar = len.map_or_else(indicatif::ProgressBar::no_length, |n| {
        indicatif::ProgressBar::new(n as u64)
    });
    let template = if len.is_some() {
        "{msg:>8} [{bar:40}] {pos}/{len} frames {per_sec} eta {eta}"
    } else {
        "{msg:>8} {spinner} {pos} frames {per_sec}"
    };
    if let Ok(style) = indicatif::ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_message("tracking");
    Some(bar)
}
