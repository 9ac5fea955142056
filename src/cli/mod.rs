//! The command line's drivers: what `polymap extract`, `replay`, `eval`, `bench` and
//! `inspect` do and print, in the library so that main.rs is only the argument parsing.

pub mod bench;
pub mod eval;
pub mod extract;
pub mod inspect;
pub mod replay;

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar of `len` frames, drawn only on a terminal.
pub fn progress(len: u64, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} frames, {eta} left").expect("valid template"),
    );
    bar.set_message(what.to_string());
    bar
}
