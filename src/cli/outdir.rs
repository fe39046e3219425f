//! The binary's side of run folders ([`rccar::run_dir`]): the start time from the wall clock
//! and the local UTC offset, the command line, and the lines that tell the user where the run
//! went. `sim`, `replay` and `drive` call [`create`] once before they write anything,
//! [`started`] just before their loop and [`finish`] at the end.

use super::signals::{say, say_err};
use anyhow::Result;
use rccar::run_dir::{RunDir, RunEnd, RunRequest, RunStart, RunState, Target};
use std::path::Path;

/// The start of a run of `command`, now.
pub fn start(command: &str) -> RunStart {
    let unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs() as i64);
    RunStart {
        command: command.to_string(),
        argv: std::env::args_os().map(|a| a.to_string_lossy().into_owned()).collect(),
        unix_s,
        utc_offset_s: utc_offset_s(unix_s),
        pid: std::process::id(),
        version: env!("CARGO_PKG_VERSION").to_string(),
    }
}

/// Local time minus UTC at `unix_s`, seconds (the C library's `localtime_r`, so `TZ` counts).
#[cfg(unix)]
fn utc_offset_s(unix_s: i64) -> i32 {
    let t = unix_s as libc::time_t;
    // SAFETY: localtime_r only writes the tm we own.
    let mut tm: libc::tm = unsafe { std::mem::zeroed() };
    let ok = unsafe { !libc::localtime_r(&t, &mut tm).is_null() };
    if ok {
        tm.tm_gmtoff as i32
    } else {
        0
    }
}

#[cfg(not(unix))]
fn utc_offset_s(_unix_s: i64) -> i32 {
    0
}

/// The run folder of `command`: `out` when given (new or empty), else a new folder under
/// `default_parent`. `also`: more folders the run fills (`--record DIR`), checked and made
/// with it; `reads`: folders the run reads, which no output may be in. Prints the new folder's
/// name when the user did not choose it (`--out` given: the user knows it).
pub fn create(
    command: &str,
    out: Option<&Path>,
    default_parent: &str,
    also: &[(&str, Option<&Path>)],
    reads: &[(&str, &Path)],
) -> Result<RunDir> {
    let mut req = RunRequest::new(match out {
        Some(p) => Target::Explicit(p.to_path_buf()),
        None => Target::Under(default_parent.into()),
    });
    req.also = also
        .iter()
        .filter_map(|(flag, p)| p.map(|p| (flag.to_string(), p.to_path_buf())))
        .collect();
    req.reads = reads
        .iter()
        .map(|(flag, p)| (flag.to_string(), p.to_path_buf()))
        .collect();
    let run = RunDir::create(&req, &start(command))?;
    if out.is_none() {
        say(&format!("{command}: run folder {}/", run.path().display()));
    }
    Ok(run)
}

/// Marks the run as started (just before the loop); a `latest` that cannot be updated is a
/// warning, not the end of the run.
pub fn started(run: &mut RunDir) {
    if let Err(e) = run.started() {
        say_err(&format!("warning: {e} (the run goes on; its folder is {})", run.path().display()));
    }
}

/// Records how the run ended in its run.json.
pub fn finish(run: &mut RunDir, state: RunState, telemetry_frames: Option<u64>) -> Result<()> {
    run.finish(RunEnd {
        state,
        telemetry_frames,
    })?;
    Ok(())
}
