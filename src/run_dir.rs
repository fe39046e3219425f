//! Output folders are runs: a run never destroys or mixes another (issue 24).
//!
//! Every run of `rccar sim`, `replay` or `drive` writes into a folder of its own:
//!
//! - **An explicit folder** (`--out DIR`, and the other folders a run fills, `--record DIR`)
//!   must be new or empty. One that holds anything is refused before anything is created or
//!   written, and the message says what it holds and the fix: `--out DIR: holds a run of
//!   2026-11-25 14:30:12 (1234 frames); choose another --out, or remove it`. An output folder
//!   equal to or inside a folder the run reads (the recording being replayed) is refused too.
//! - **The default place** (`out/sim`, `out/replay`, `out/drive`) is a parent: each run makes a
//!   new folder `<parent>/<YYYYmmdd-HHMMSS>[-N]/` (local time; `-2`, `-3`, … when runs start in
//!   the same second) and `<parent>/latest`, a symlink replaced atomically, points at the
//!   newest run that started.
//!
//! Layout of a run folder:
//!
//! ```text
//! run.json          written first: run_id, command, argv, started, rccar_version and
//!                   state "running"; written again (atomically) when the run ends, with its
//!                   state, telemetry_frames and the files it wrote
//! telemetry.jsonl   one line per frame, appended while the run goes
//! summary.json,     written atomically (a temporary file, then a rename), so they appear
//! config.json, …    whole or not at all; the JSON ones carry the run's "run_id"
//! ```
//!
//! A run that fails before its loop starts ([`RunDir::started`] not called yet) leaves nothing
//! behind: dropping its [`RunDir`] removes what it created (the run folder, the `--record`
//! folders, parent folders it had to make when they are empty again), and empties again an
//! explicit folder that was empty.
//!
//! [`check_run`] is the other side: `rccar report` asks it whether the files of a folder
//! belong to one run (run ids agree, the telemetry has the frames the run wrote, every plot is
//! the run's own).
//!
//! The library reads no clock: the caller gives the start time and its UTC offset
//! ([`RunStart`]). Units: seconds since 1970-01-01 UTC.

use serde::{Deserialize, Serialize};
use std::io::{Read, Write};
use std::path::{Component, Path, PathBuf};

/// Name of the run's own record inside a run folder.
pub const RUN_FILE: &str = "run.json";
/// Name of the symlink in a default parent that points at the newest run.
pub const LATEST: &str = "latest";
/// Name of the telemetry file of a run.
pub const TELEMETRY_FILE: &str = "telemetry.jsonl";
/// Runs that may start in one second under one parent (`-2` … `-999`).
const MAX_SAME_SECOND: u32 = 999;

/// When and how a run started, as the caller (who has a clock) saw it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunStart {
    /// The subcommand (`sim`, `replay`, `drive`).
    pub command: String,
    /// The whole command line, for the record.
    pub argv: Vec<String>,
    /// Start time, seconds since 1970-01-01 UTC.
    pub unix_s: i64,
    /// Local time minus UTC at the start, seconds (folder names and dates are local time).
    pub utc_offset_s: i32,
    /// The process id (part of the run id: two processes never share one).
    pub pid: u32,
    /// rccar's version.
    pub version: String,
}

impl RunStart {
    /// The start as a folder name: local time `YYYYmmdd-HHMMSS`.
    pub fn stamp(&self) -> String {
        let c = Civil::from_unix(self.unix_s + i64::from(self.utc_offset_s));
        format!(
            "{:04}{:02}{:02}-{:02}{:02}{:02}",
            c.year, c.month, c.day, c.hour, c.minute, c.second
        )
    }

    /// The start in ISO 8601 with the UTC offset, e.g. `2026-11-25T14:30:12+01:00`.
    pub fn iso(&self) -> String {
        iso8601(self.unix_s, self.utc_offset_s)
    }

    /// The run id: the start stamp and the process id (`20261125-143012-4242`).
    pub fn run_id(&self) -> String {
        format!("{}-{}", self.stamp(), self.pid)
    }
}

/// A calendar date and time of day (proleptic Gregorian).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Civil {
    year: i64,
    month: u32,
    day: u32,
    hour: u32,
    minute: u32,
    second: u32,
}

impl Civil {
    /// Seconds since 1970-01-01 (already shifted to the wanted time zone) → date and time.
    /// Days → date by H. Hinnant's `civil_from_days` (exact for every i64 day count in range).
    fn from_unix(t: i64) -> Civil {
        let days = t.div_euclid(86_400);
        let secs = t.rem_euclid(86_400) as u32;
        // 1. Shift the epoch to 0000-03-01, so leap days end a 400-year era.
        let z = days + 719_468;
        let era = z.div_euclid(146_097);
        let doe = z.rem_euclid(146_097); // day of era, 0..=146096
                                         // 2. Year of era, day of year (from March 1), month (March = 0).
        let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
        let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
        let mp = (5 * doy + 2) / 153;
        // 3. Back to January-based months.
        let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
        let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
        let year = yoe + era * 400 + i64::from(month <= 2);
        Civil {
            year,
            month,
            day,
            hour: secs / 3600,
            minute: secs / 60 % 60,
            second: secs % 60,
        }
    }
}

/// `unix_s` as ISO 8601 local time with its offset: `2026-11-25T14:30:12+01:00`.
pub fn iso8601(unix_s: i64, utc_offset_s: i32) -> String {
    let c = Civil::from_unix(unix_s + i64::from(utc_offset_s));
    let off = utc_offset_s.unsigned_abs();
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}{}{:02}:{:02}",
        c.year,
        c.month,
        c.day,
        c.hour,
        c.minute,
        c.second,
        if utc_offset_s < 0 { '-' } else { '+' },
        off / 3600,
        off / 60 % 60
    )
}

/// An ISO 8601 time as people read it: `2026-11-25T14:30:12+01:00` → `2026-11-25 14:30:12`.
fn readable(iso: &str) -> String {
    match iso.get(..19) {
        Some(s) if iso.len() >= 19 => s.replacen('T', " ", 1),
        _ => iso.to_string(),
    }
}

/// Where a run's output goes.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Target {
    /// A folder named by the user (`--out DIR`): must be new or empty.
    Explicit(PathBuf),
    /// A default parent (`out/sim`): a new folder per run under it, and `latest`.
    Under(PathBuf),
}

/// What a run will write and read, checked before anything is created.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RunRequest {
    /// The run folder.
    pub target: Target,
    /// The flag that names the target in messages (`--out`).
    pub flag: String,
    /// More folders the run fills, with their flags (`--record DIR`): new or empty, made with
    /// the run folder, removed with it if the run never starts.
    pub also: Vec<(String, PathBuf)>,
    /// Folders the run reads, with their flags (the recording being replayed): no output
    /// folder may be one of them or inside one.
    pub reads: Vec<(String, PathBuf)>,
}

impl RunRequest {
    /// A request for `target` named by `--out`, with no other folders.
    pub fn new(target: Target) -> Self {
        Self {
            target,
            flag: "--out".into(),
            also: Vec::new(),
            reads: Vec::new(),
        }
    }
}

/// Why a run folder cannot be used. Every variant names the folder and the flag.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// The folder holds a run or a recording.
    #[error("{flag} {path}: holds {what}; choose another {flag}, or remove it", path = path.display())]
    HoldsRun {
        /// The flag that named it.
        flag: String,
        /// The folder.
        path: PathBuf,
        /// What it holds: "a run of 2026-11-25 14:30:12 (1234 frames)", "30 frames (a recording)".
        what: String,
    },
    /// The folder holds something else.
    #[error("{flag} {path}: not empty ({what}); choose another {flag} (a new or empty folder), or remove it", path = path.display())]
    NotEmpty {
        /// The flag that named it.
        flag: String,
        /// The folder.
        path: PathBuf,
        /// Some of what is in it.
        what: String,
    },
    /// The path is a file.
    #[error("{flag} {path}: is a file, not a folder; choose another {flag}", path = path.display())]
    NotAFolder {
        /// The flag that named it.
        flag: String,
        /// The path.
        path: PathBuf,
    },
    /// An output folder is one the run reads, or inside one.
    #[error("{flag} {path}: is {how} {input_flag} {input}, which this run reads; choose an output folder outside it", path = path.display(), input = input.display())]
    InsideInput {
        /// The output's flag.
        flag: String,
        /// The output folder.
        path: PathBuf,
        /// "the same folder as" or "inside".
        how: &'static str,
        /// The input's flag.
        input_flag: String,
        /// The input folder.
        input: PathBuf,
    },
    /// A folder cannot be created.
    #[error("{path}: cannot create: {err}", path = path.display())]
    Create {
        /// The folder.
        path: PathBuf,
        /// Underlying error (in the message, not a `source`: printed once).
        err: std::io::Error,
    },
    /// A file of the run cannot be written.
    #[error("{path}: cannot write: {err}", path = path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Underlying error (in the message, not a `source`: printed once).
        err: std::io::Error,
    },
    /// A file cannot be read.
    #[error("{path}: cannot read: {err}", path = path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Underlying error (in the message, not a `source`: printed once).
        err: std::io::Error,
    },
    /// A value cannot be written as JSON.
    #[error("{path}: cannot write as JSON: {message}", path = path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// The serializer's message.
        message: String,
    },
    /// An image cannot be encoded as PNG.
    #[error("{path}: cannot encode PNG: {message}", path = path.display())]
    Png {
        /// The file.
        path: PathBuf,
        /// The encoder's message.
        message: String,
    },
    /// A run folder to read is not a folder.
    #[error("{path}: not a folder (give a run's output folder, e.g. out/sim/latest)", path = path.display())]
    NotARunFolder {
        /// The path given.
        path: PathBuf,
    },
    /// A run folder to read holds neither summary.json nor telemetry.jsonl.
    #[error("{path}: neither summary.json nor telemetry.jsonl here; run `rccar sim --out {path}` or `rccar replay FRAMES --out {path}` first", path = path.display())]
    NoRun {
        /// The folder.
        path: PathBuf,
    },
    /// Every name for this second is taken.
    #[error("{parent}: {max} runs already started at {stamp}; wait a second or give --out", parent = parent.display(), max = MAX_SAME_SECOND)]
    NoFreeName {
        /// The parent folder.
        parent: PathBuf,
        /// The second's stamp.
        stamp: String,
    },
}

/// How a run ended, in its run.json.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RunState {
    /// Started and not ended yet (or killed without a word).
    Running,
    /// Ran to its end.
    Finished,
    /// Stopped by Ctrl-C, SIGTERM or another stop request; the files cover what ran.
    Interrupted,
    /// Ended by an error after it started.
    Failed,
}

impl RunState {
    /// The state of a run whose loop ended by `stop` (`None`: it ran to its end): Ctrl-C and
    /// SIGTERM, SIGHUP and SIGQUIT interrupt, a fault fails, a requested stop (`--seconds`, the button) finishes.
    pub fn from_stop(stop: Option<crate::drive::StopReason>) -> RunState {
        use crate::drive::StopReason;
        match stop {
            None | Some(StopReason::Requested) => RunState::Finished,
            Some(StopReason::Interrupt | StopReason::Terminate | StopReason::Hangup | StopReason::Quit) => RunState::Interrupted,
            Some(StopReason::Fault) => RunState::Failed,
        }
    }
}

/// The contents of run.json.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRecord {
    /// The run's id ([`RunStart::run_id`]); summary.json and config.json carry it too.
    pub run_id: String,
    /// The subcommand.
    pub command: String,
    /// The command line.
    #[serde(default)]
    pub argv: Vec<String>,
    /// Start, ISO 8601 local time with offset.
    pub started: String,
    /// rccar's version.
    pub rccar_version: String,
    /// How the run ended (or `running`).
    pub state: RunState,
    /// Telemetry lines the run wrote (at the end; `None` without telemetry).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub telemetry_frames: Option<u64>,
    /// Files and folders the run wrote into its folder (at the end).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub files: Vec<String>,
}

/// How a run ended, for [`RunDir::finish`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunEnd {
    /// The state to record.
    pub state: RunState,
    /// Telemetry lines written (`None`: the run writes no telemetry, e.g. a sweep).
    pub telemetry_frames: Option<u64>,
}

/// One run's output folder. See the module documentation.
#[derive(Debug)]
pub struct RunDir {
    path: PathBuf,
    parent: Option<PathBuf>,
    record: RunRecord,
    started: bool,
    /// Folders this run made (removed whole if it never starts).
    made: Vec<PathBuf>,
    /// Explicit folders that existed empty (emptied again if it never starts).
    were_empty: Vec<PathBuf>,
    /// Parent folders made on the way (removed if empty, deepest first).
    ancestors: Vec<PathBuf>,
    files: std::collections::BTreeSet<String>,
}

impl RunDir {
    /// Checks every folder of `req` (new or empty, not a file, not inside what the run reads),
    /// then creates the run folder and the `also` folders and writes run.json. Nothing is
    /// created when a check fails; if creating fails part-way, what was made is removed.
    pub fn create(req: &RunRequest, start: &RunStart) -> Result<RunDir, RunDirError> {
        // 1. Every output folder: the target (or the parent it goes under) and the others.
        let mut outputs: Vec<(&str, &Path)> = Vec::new();
        let target_path = match &req.target {
            Target::Explicit(p) | Target::Under(p) => p.as_path(),
        };
        outputs.push((req.flag.as_str(), target_path));
        for (flag, p) in &req.also {
            outputs.push((flag.as_str(), p.as_path()));
        }
        for (i, (flag, p)) in outputs.iter().enumerate() {
            let resolved = resolve(p);
            for (input_flag, input) in &req.reads {
                let inp = resolve(input);
                if resolved.starts_with(&inp) {
                    return Err(RunDirError::InsideInput {
                        flag: flag.to_string(),
                        path: p.to_path_buf(),
                        how: if resolved == inp {
                            "the same folder as"
                        } else {
                            "inside"
                        },
                        input_flag: input_flag.clone(),
                        input: input.clone(),
                    });
                }
            }
            let under = i == 0 && matches!(req.target, Target::Under(_));
            if under {
                if p.exists() && !p.is_dir() {
                    return Err(RunDirError::NotAFolder {
                        flag: flag.to_string(),
                        path: p.to_path_buf(),
                    });
                }
            } else {
                check_new_or_empty(flag, p, start.utc_offset_s)?;
            }
        }

        // 2. Create, remembering what to take back if the run never starts.
        let record = RunRecord {
            run_id: start.run_id(),
            command: start.command.clone(),
            argv: start.argv.clone(),
            started: start.iso(),
            rccar_version: start.version.clone(),
            state: RunState::Running,
            telemetry_frames: None,
            files: Vec::new(),
        };
        let mut run = RunDir {
            path: PathBuf::new(),
            parent: None,
            record,
            started: false,
            made: Vec::new(),
            were_empty: Vec::new(),
            ancestors: Vec::new(),
            files: Default::default(),
        };
        match &req.target {
            Target::Explicit(p) => {
                run.make_explicit(p)?;
                run.path = p.clone();
            }
            Target::Under(parent) => {
                run.path = run.make_under(parent, &start.stamp())?;
                run.parent = Some(parent.clone());
            }
        }
        let target_resolved = resolve(&run.path);
        for (_, p) in &req.also {
            if resolve(p) != target_resolved {
                run.make_explicit(p)?;
            }
        }
        // 3. run.json first.
        run.write_record()?;
        Ok(run)
    }

    /// The run folder.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The run's id.
    pub fn id(&self) -> &str {
        &self.record.run_id
    }

    /// `path/name`.
    pub fn join(&self, name: &str) -> PathBuf {
        self.path.join(name)
    }

    /// Marks the run as started (call it just before the loop): from now on nothing is removed
    /// when the `RunDir` is dropped, and `latest` of a default parent points at this run. An
    /// error here is only about `latest` (the run can go on; show it as a warning).
    pub fn started(&mut self) -> Result<(), RunDirError> {
        self.started = true;
        match &self.parent {
            Some(parent) => point_latest(parent, &self.path),
            None => Ok(()),
        }
    }

    /// Writes `name` in the run folder atomically (a temporary file beside it, synced, then
    /// renamed over the name): a reader sees the old file or the whole new one.
    pub fn write(&mut self, name: &str, bytes: &[u8]) -> Result<PathBuf, RunDirError> {
        let path = self.path.join(name);
        write_atomic(&path, bytes).map_err(|err| RunDirError::Write {
            path: path.clone(),
            err,
        })?;
        self.files.insert(name.to_string());
        Ok(path)
    }

    /// Writes `img` as PNG (a plot), atomically, as `name`; returns its path.
    pub fn write_png(&mut self, name: &str, img: &image::RgbImage) -> Result<PathBuf, RunDirError> {
        let mut png = std::io::Cursor::new(Vec::new());
        img.write_to(&mut png, image::ImageFormat::Png).map_err(|e| RunDirError::Png {
            path: self.path.join(name),
            message: e.to_string(),
        })?;
        self.write(name, &png.into_inner())
    }

    /// Writes `value` as pretty JSON, atomically, with the run's id as its first key
    /// `"run_id"` (when it is an object), so `rccar report` can tell whose it is.
    pub fn write_json<T: Serialize + ?Sized>(&mut self, name: &str, value: &T) -> Result<PathBuf, RunDirError> {
        let text = serde_json::to_string_pretty(value).map_err(|e| RunDirError::Json {
            path: self.path.join(name),
            message: e.to_string(),
        })?;
        let id = serde_json::to_string(&self.record.run_id).unwrap_or_default();
        let text = if let Some(rest) = text.strip_prefix("{\n") {
            format!("{{\n  \"run_id\": {id},\n{rest}\n")
        } else if text == "{}" {
            format!("{{\n  \"run_id\": {id}\n}}\n")
        } else {
            text + "\n"
        };
        self.write(name, text.as_bytes())
    }

    /// Records that `name` (a file or folder in the run folder written by someone else, such
    /// as the telemetry writer) is this run's.
    pub fn note_file(&mut self, name: &str) {
        self.files.insert(name.to_string());
    }

    /// Writes run.json again, atomically, with how the run ended, its telemetry count and
    /// the files it wrote. Also marks the run as started (an ended run is never removed).
    pub fn finish(&mut self, end: RunEnd) -> Result<(), RunDirError> {
        self.started = true;
        self.record.state = end.state;
        self.record.telemetry_frames = end.telemetry_frames;
        if end.telemetry_frames.is_some() {
            self.files.insert(TELEMETRY_FILE.to_string());
        }
        self.write_record()
    }

    fn write_record(&mut self) -> Result<(), RunDirError> {
        let mut r = self.record.clone();
        r.files = self.files.iter().cloned().collect();
        let text = serde_json::to_string_pretty(&r).map_err(|e| RunDirError::Json {
            path: self.path.join(RUN_FILE),
            message: e.to_string(),
        })? + "\n";
        let path = self.path.join(RUN_FILE);
        write_atomic(&path, text.as_bytes()).map_err(|err| RunDirError::Write { path, err })
    }

    /// Makes an explicit folder (checked new or empty before), remembering what it made.
    fn make_explicit(&mut self, p: &Path) -> Result<(), RunDirError> {
        if p.is_dir() {
            // It was checked empty; this run fills it (unless an earlier folder of this run
            // was made inside it, which makes it this run's already).
            if !self.made.iter().any(|m| resolve(m).starts_with(resolve(p))) {
                self.were_empty.push(p.to_path_buf());
            }
            return Ok(());
        }
        // Parents that do not exist yet, outermost first.
        let mut missing = Vec::new();
        let mut a = p.parent();
        while let Some(d) = a {
            if d.as_os_str().is_empty() || d.exists() {
                break;
            }
            missing.push(d.to_path_buf());
            a = d.parent();
        }
        std::fs::create_dir_all(p).map_err(|err| RunDirError::Create {
            path: p.to_path_buf(),
            err,
        })?;
        self.ancestors.extend(missing);
        self.made.push(p.to_path_buf());
        Ok(())
    }

    /// Makes `parent/stamp` (or `stamp-2`, …), the first name that is free.
    fn make_under(&mut self, parent: &Path, stamp: &str) -> Result<PathBuf, RunDirError> {
        if !parent.is_dir() {
            let mut missing = vec![parent.to_path_buf()];
            let mut a = parent.parent();
            while let Some(d) = a {
                if d.as_os_str().is_empty() || d.exists() {
                    break;
                }
                missing.push(d.to_path_buf());
                a = d.parent();
            }
            std::fs::create_dir_all(parent).map_err(|err| RunDirError::Create {
                path: parent.to_path_buf(),
                err,
            })?;
            self.ancestors.extend(missing);
        }
        for n in 1..=MAX_SAME_SECOND {
            let name = if n == 1 {
                stamp.to_string()
            } else {
                format!("{stamp}-{n}")
            };
            let dir = parent.join(&name);
            match std::fs::create_dir(&dir) {
                Ok(()) => {
                    self.made.push(dir.clone());
                    return Ok(dir);
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(err) => return Err(RunDirError::Create { path: dir, err }),
            }
        }
        Err(RunDirError::NoFreeName {
            parent: parent.to_path_buf(),
            stamp: stamp.to_string(),
        })
    }
}

impl Drop for RunDir {
    /// A run that never started takes back what it made.
    fn drop(&mut self) {
        if self.started {
            return;
        }
        for d in &self.made {
            let _ = std::fs::remove_dir_all(d);
        }
        for d in &self.were_empty {
            if let Ok(rd) = std::fs::read_dir(d) {
                for e in rd.flatten() {
                    let p = e.path();
                    let _ = if e.file_type().is_ok_and(|t| t.is_dir()) {
                        std::fs::remove_dir_all(&p)
                    } else {
                        std::fs::remove_file(&p)
                    };
                }
            }
        }
        // Deepest first; only when empty (another run may have started in a shared parent).
        let mut anc = self.ancestors.clone();
        anc.sort_by_key(|p| std::cmp::Reverse(p.components().count()));
        for d in anc {
            let _ = std::fs::remove_dir(d);
        }
    }
}

/// Writes `path` atomically: `.NAME.tmp-PID` beside it, synced, renamed over `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "no file name"))?;
    let tmp = path.with_file_name(format!(".{}.tmp-{}", name.to_string_lossy(), std::process::id()));
    let r = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if r.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    r
}

/// Points `parent/latest` at `run` (a relative symlink made beside it, renamed over it).
fn point_latest(parent: &Path, run: &Path) -> Result<(), RunDirError> {
    #[cfg(unix)]
    {
        let latest = parent.join(LATEST);
        let name = run.file_name().map(PathBuf::from).unwrap_or_else(|| run.to_path_buf());
        let tmp = parent.join(format!(".{LATEST}.tmp-{}", std::process::id()));
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(&name, &tmp)
            .and_then(|()| std::fs::rename(&tmp, &latest))
            .map_err(|err| {
                let _ = std::fs::remove_file(&tmp);
                RunDirError::Write { path: latest, err }
            })
    }
    #[cfg(not(unix))]
    {
        let _ = (parent, run);
        Ok(())
    }
}

/// The absolute form of `p` with symlinks of its existing part resolved and `.`/`..` of the
/// rest taken lexically (for "is this folder inside that one").
fn resolve(p: &Path) -> PathBuf {
    let abs = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut lexical = PathBuf::new();
    for c in abs.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                lexical.pop();
            }
            c => lexical.push(c),
        }
    }
    let mut existing = lexical.clone();
    let mut rest = Vec::new();
    loop {
        if let Ok(mut c) = existing.canonicalize() {
            for r in rest.iter().rev() {
                c.push(r);
            }
            return c;
        }
        match (existing.file_name().map(|n| n.to_os_string()), existing.parent()) {
            (Some(n), Some(parent)) => {
                rest.push(n);
                existing = parent.to_path_buf();
            }
            _ => return lexical,
        }
    }
}

/// Refuses a folder that exists and is not empty (or is a file), saying what it holds.
pub fn check_new_or_empty(flag: &str, p: &Path, utc_offset_s: i32) -> Result<(), RunDirError> {
    let meta = match std::fs::metadata(p) {
        Ok(m) => m,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(err) => {
            return Err(RunDirError::Read {
                path: p.to_path_buf(),
                err,
            })
        }
    };
    if !meta.is_dir() {
        return Err(RunDirError::NotAFolder {
            flag: flag.to_string(),
            path: p.to_path_buf(),
        });
    }
    let mut names: Vec<String> = std::fs::read_dir(p)
        .map_err(|err| RunDirError::Read {
            path: p.to_path_buf(),
            err,
        })?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    if names.is_empty() {
        return Ok(());
    }
    names.sort();
    match describe_run(p, &names, utc_offset_s) {
        Some(what) => Err(RunDirError::HoldsRun {
            flag: flag.to_string(),
            path: p.to_path_buf(),
            what,
        }),
        None => {
            let shown: Vec<&str> = names.iter().take(3).map(String::as_str).collect();
            let more = if names.len() > 3 { ", …" } else { "" };
            Err(RunDirError::NotEmpty {
                flag: flag.to_string(),
                path: p.to_path_buf(),
                what: format!(
                    "{} entr{}: {}{more}",
                    names.len(),
                    if names.len() == 1 { "y" } else { "ies" },
                    shown.join(", ")
                ),
            })
        }
    }
}

/// "a run of DATE (N frames)" for a run folder (run.json, or an older rccar's telemetry or
/// summary), "N frames (a recording)" for a folder of frames; `None` for anything else.
fn describe_run(dir: &Path, names: &[String], utc_offset_s: i32) -> Option<String> {
    let has = |n: &str| names.iter().any(|x| x == n);
    let tel = dir.join(TELEMETRY_FILE);
    let frames = || {
        count_lines(&tel)
            .ok()
            .map(|n| format!(" ({n} frames)"))
            .unwrap_or_default()
    };
    if has(RUN_FILE) {
        let rec = read_record(&dir.join(RUN_FILE)).ok();
        let date = rec
            .as_ref()
            .map_or_else(|| "an unknown date".to_string(), |r| readable(&r.started));
        let n = match rec.as_ref().and_then(|r| r.telemetry_frames) {
            Some(n) => format!(" ({n} frames)"),
            None if tel.is_file() => frames(),
            None => String::new(),
        };
        return Some(format!("a run of {date}{n}"));
    }
    if has(TELEMETRY_FILE) || has("summary.json") || has("sweep.csv") {
        let newest = [TELEMETRY_FILE, "summary.json", "sweep.csv"]
            .iter()
            .filter_map(|n| std::fs::metadata(dir.join(n)).and_then(|m| m.modified()).ok())
            .max()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok());
        let date = newest.map_or_else(
            || "an unknown date".to_string(),
            |d| readable(&iso8601(d.as_secs() as i64, utc_offset_s)),
        );
        return Some(format!(
            "a run of {date}{}",
            if tel.is_file() { frames() } else { String::new() }
        ));
    }
    let n = count_frames(dir);
    (n > 0).then(|| format!("{n} frames (a recording)"))
}

/// Image files in `dir` and its `seg_*` folders (a recording's frames).
fn count_frames(dir: &Path) -> usize {
    let is_frame = |p: &Path| {
        p.extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
    };
    let Ok(rd) = std::fs::read_dir(dir) else { return 0 };
    let mut n = 0;
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir()
            && e.file_name()
                .to_string_lossy()
                .starts_with(crate::record::SEGMENT_PREFIX)
        {
            n += std::fs::read_dir(&p).map_or(0, |r| r.flatten().filter(|e| is_frame(&e.path())).count());
        } else if is_frame(&p) {
            n += 1;
        }
    }
    n
}

/// Lines of a file (a last line without its newline counts), read in blocks.
pub fn count_lines(path: &Path) -> Result<u64, RunDirError> {
    let mut f = std::fs::File::open(path).map_err(|err| RunDirError::Read {
        path: path.to_path_buf(),
        err,
    })?;
    let mut buf = vec![0u8; 64 * 1024];
    let (mut n, mut last) = (0u64, b'\n');
    loop {
        let k = f.read(&mut buf).map_err(|err| RunDirError::Read {
            path: path.to_path_buf(),
            err,
        })?;
        if k == 0 {
            break;
        }
        n += buf[..k].iter().filter(|&&b| b == b'\n').count() as u64;
        last = buf[k - 1];
    }
    Ok(n + u64::from(last != b'\n'))
}

fn read_record(path: &Path) -> Result<RunRecord, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{}: not a run record: {e}", path.display()))
}

/// What [`check_run`] found in a folder.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunCheck {
    /// The folder's run.json, when it has one that reads.
    pub record: Option<RunRecord>,
    /// Files of different runs side by side: each names the files and what disagrees.
    pub problems: Vec<String>,
    /// What could not be checked (an older rccar's folder, a run that has not ended).
    pub notes: Vec<String>,
    /// Files in the folder the run did not write (plots put there later): not part of the run.
    pub foreign: Vec<String>,
}

impl RunCheck {
    /// Whether `name` (a file in the folder) belongs to the run as far as can be told.
    pub fn is_foreign(&self, name: &str) -> bool {
        self.foreign.iter().any(|f| f == name)
    }
}

/// The newest run of `given` when it is a folder of runs (no run's files of its own, and a
/// `latest` folder), else `None` (`given` itself is the run); an error when `given` is not a
/// folder.
pub fn newest_run(given: &Path) -> Result<Option<PathBuf>, RunDirError> {
    if !given.is_dir() {
        return Err(RunDirError::NotARunFolder { path: given.to_path_buf() });
    }
    let is_run = |d: &Path| ["summary.json", "telemetry.jsonl", RUN_FILE].iter().any(|f| d.join(f).is_file());
    let latest = given.join(LATEST);
    if is_run(given) || !latest.is_dir() {
        return Ok(None);
    }
    Ok(Some(std::fs::read_link(&latest).map_or_else(|_| latest.clone(), |t| given.join(t))))
}

/// Refuses a folder without summary.json or telemetry.jsonl (nothing to read as a run).
pub fn has_run_files(dir: &Path) -> Result<(), RunDirError> {
    if !dir.join("summary.json").is_file() && !dir.join("telemetry.jsonl").is_file() {
        return Err(RunDirError::NoRun { path: dir.to_path_buf() });
    }
    Ok(())
}

/// Whether the files of run folder `dir` belong to one run: run.json, summary.json and
/// config.json carry one run id; the telemetry has as many lines as run.json and summary.json
/// say the run wrote; every summary file and plot is in run.json's list of the run's files.
/// A folder without run.json (an older rccar) gets the frame counts checked and a note.
pub fn check_run(dir: &Path) -> Result<RunCheck, RunDirError> {
    let mut c = RunCheck::default();
    let run_path = dir.join(RUN_FILE);
    if run_path.is_file() {
        match read_record(&run_path) {
            Ok(r) => c.record = Some(r),
            Err(e) => c.problems.push(e),
        }
    } else {
        c.notes.push(format!(
            "{}: no {RUN_FILE} (an older rccar's folder, or files put together by hand): only the frame counts can be checked",
            dir.display()
        ));
    }
    // 1. Run ids of the JSON summaries.
    let summary_frames = check_ids(dir, &mut c)?;
    // 2. The telemetry's frames.
    let tel = dir.join(TELEMETRY_FILE);
    let tel_lines = if tel.is_file() { Some(count_lines(&tel)?) } else { None };
    if let Some(n) = tel_lines {
        if let Some(m) = summary_frames {
            if m != n {
                c.problems.push(format!(
                    "{TELEMETRY_FILE} has {n} frames, summary.json says the run had {m}"
                ));
            }
        }
    }
    if let Some(r) = c.record.clone() {
        match (r.state, r.telemetry_frames, tel_lines) {
            (RunState::Running, ..) => c.notes.push(format!(
                "{RUN_FILE}: run {} has not ended (still running, or it was killed): the files cover what it wrote",
                r.run_id
            )),
            (_, Some(m), Some(n)) if m != n => c.problems.push(format!(
                "{TELEMETRY_FILE} has {n} frames, {RUN_FILE} says run {} wrote {m}",
                r.run_id
            )),
            (_, Some(m), None) => c.problems.push(format!(
                "{TELEMETRY_FILE} is missing; run {} wrote {m} frames",
                r.run_id
            )),
            _ => {}
        }
        // 3. Every file is one the run wrote.
        if r.state != RunState::Running {
            check_files(dir, &r, &mut c)?;
        }
    }
    Ok(c)
}

/// The run ids of summary.json and config.json against run.json's (or each other's, without
/// one); returns the frames summary.json counts.
fn check_ids(dir: &Path, c: &mut RunCheck) -> Result<Option<u64>, RunDirError> {
    let id = c.record.as_ref().map(|r| r.run_id.clone());
    let mut ids: Vec<(&str, Option<String>)> = Vec::new();
    let mut summary_frames = None;
    for name in ["summary.json", "config.json"] {
        let p = dir.join(name);
        if !p.is_file() {
            continue;
        }
        let text = std::fs::read_to_string(&p).map_err(|err| RunDirError::Read {
            path: p.clone(),
            err,
        })?;
        let v: serde_json::Value = match serde_json::from_str(&text) {
            Ok(v) => v,
            Err(e) => {
                c.problems.push(format!("{name}: not JSON ({e})"));
                continue;
            }
        };
        if name == "summary.json" {
            summary_frames = v.get("frames").and_then(serde_json::Value::as_u64);
        }
        ids.push((name, v.get("run_id").and_then(|x| x.as_str()).map(String::from)));
    }
    match &id {
        Some(id) => {
            for (name, theirs) in &ids {
                match theirs {
                    Some(t) if t == id => {}
                    Some(t) => c
                        .problems
                        .push(format!("{name} is run {t}'s, {RUN_FILE} is run {id}'s")),
                    None => c.problems.push(format!(
                        "{name} has no run_id: not written by run {id} (an older rccar's file, or copied in)"
                    )),
                }
            }
        }
        None => {
            if let [(a, Some(x)), (b, Some(y))] = ids.as_slice() {
                if x != y {
                    c.problems.push(format!("{a} is run {x}'s, {b} is run {y}'s"));
                }
            }
        }
    }
    Ok(summary_frames)
}

/// Every data file and plot in `dir` is one run `r` wrote: a data file that is not is a
/// problem, a plot that is not is left out (foreign).
fn check_files(dir: &Path, r: &RunRecord, c: &mut RunCheck) -> Result<(), RunDirError> {
    let rd = std::fs::read_dir(dir).map_err(|err| RunDirError::Read {
        path: dir.to_path_buf(),
        err,
    })?;
    let mut names: Vec<String> = rd
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    for n in names {
        let data = matches!(
            n.as_str(),
            "summary.json" | "config.json" | TELEMETRY_FILE | "sweep.csv"
        );
        let plot = n.to_ascii_lowercase().ends_with(".png") && !n.starts_with("frame_");
        if (data || plot) && !r.files.contains(&n) {
            if data {
                c.problems.push(format!(
                    "{n} was not written by run {} (not in {RUN_FILE}'s files)",
                    r.run_id
                ));
            } else {
                c.foreign.push(n);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn start(unix_s: i64, pid: u32) -> RunStart {
        RunStart {
            command: "sim".into(),
            argv: vec!["rccar".into(), "sim".into()],
            unix_s,
            utc_offset_s: 3600,
            pid,
            version: "0.1.0".into(),
        }
    }

    #[test]
    fn dates_from_unix_seconds() {
        // Known instants (date -u -d @T).
        assert_eq!(iso8601(0, 0), "1970-01-01T00:00:00+00:00");
        assert_eq!(iso8601(951_782_400, 0), "2000-02-29T00:00:00+00:00");
        assert_eq!(iso8601(1_795_185_012, 0), "2026-11-20T14:30:12+00:00");
        assert_eq!(iso8601(1_795_185_012, 3600), "2026-11-20T15:30:12+01:00");
        assert_eq!(iso8601(1_795_185_012, -9000), "2026-11-20T12:00:12-02:30");
        assert_eq!(iso8601(-1, 0), "1969-12-31T23:59:59+00:00");
        assert_eq!(iso8601(4_107_542_400, 0), "2100-03-01T00:00:00+00:00");
        let s = start(1_795_185_012, 42);
        assert_eq!(s.stamp(), "20261120-153012");
        assert_eq!(s.run_id(), "20261120-153012-42");
        assert_eq!(readable(&s.iso()), "2026-11-20 15:30:12");
    }

    #[test]
    fn the_default_place_gets_a_new_folder_per_run_and_latest() {
        let t = tempfile::tempdir().unwrap();
        let parent = t.path().join("out/sim");
        let mut a = RunDir::create(
            &RunRequest::new(Target::Under(parent.clone())),
            &start(1_795_185_012, 1),
        )
        .unwrap();
        a.started().unwrap();
        // The same second: -2.
        let mut b = RunDir::create(
            &RunRequest::new(Target::Under(parent.clone())),
            &start(1_795_185_012, 2),
        )
        .unwrap();
        b.started().unwrap();
        assert_eq!(a.path(), parent.join("20261120-153012"));
        assert_eq!(b.path(), parent.join("20261120-153012-2"));
        assert_eq!(
            std::fs::read_link(parent.join(LATEST)).unwrap(),
            PathBuf::from("20261120-153012-2")
        );
        let rec = read_record(&b.join(RUN_FILE)).unwrap();
        assert_eq!(
            (rec.run_id.as_str(), rec.state),
            ("20261120-153012-2", RunState::Running)
        );
        assert_eq!(rec.started, "2026-11-20T15:30:12+01:00");
        // Nothing but the two runs and latest (no temporary files left).
        let mut names: Vec<String> = std::fs::read_dir(&parent)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        assert_eq!(names, ["20261120-153012", "20261120-153012-2", "latest"]);
    }

    #[test]
    fn an_explicit_folder_must_be_new_or_empty() {
        let t = tempfile::tempdir().unwrap();
        let dir = t.path().join("mine");
        let mut r = RunDir::create(
            &RunRequest::new(Target::Explicit(dir.clone())),
            &start(1_795_185_012, 1),
        )
        .unwrap();
        r.started().unwrap();
        std::fs::write(r.join(TELEMETRY_FILE), "{}\n{}\n{}\n").unwrap();
        r.finish(RunEnd {
            state: RunState::Finished,
            telemetry_frames: Some(3),
        })
        .unwrap();
        drop(r);
        let e = RunDir::create(
            &RunRequest::new(Target::Explicit(dir.clone())),
            &start(1_795_185_100, 2),
        )
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            format!(
                "--out {}: holds a run of 2026-11-20 15:30:12 (3 frames); choose another --out, or remove it",
                dir.display()
            )
        );
        // Anything else in it: not empty. A file: not a folder. Nothing was created.
        let notes = t.path().join("notes");
        std::fs::create_dir(&notes).unwrap();
        std::fs::write(notes.join("a.txt"), "x").unwrap();
        let e = RunDir::create(&RunRequest::new(Target::Explicit(notes.clone())), &start(1, 2))
            .unwrap_err()
            .to_string();
        assert!(e.contains("not empty (1 entry: a.txt)"), "{e}");
        assert_eq!(std::fs::read_dir(&notes).unwrap().count(), 1);
        let e = RunDir::create(&RunRequest::new(Target::Explicit(notes.join("a.txt"))), &start(1, 2))
            .unwrap_err()
            .to_string();
        assert!(e.contains("is a file"), "{e}");
        // A recording of frames.
        let frames = t.path().join("frames");
        std::fs::create_dir_all(frames.join("seg_000000")).unwrap();
        for k in 0..4 {
            std::fs::write(frames.join(format!("seg_000000/frame_{k:09}.jpg")), "x").unwrap();
        }
        let mut req = RunRequest::new(Target::Explicit(t.path().join("new")));
        req.also.push(("--record".into(), frames.clone()));
        let e = RunDir::create(&req, &start(1, 2)).unwrap_err().to_string();
        assert!(
            e.starts_with("--record ") && e.contains("holds 4 frames (a recording); choose another --record"),
            "{e}"
        );
        assert!(!t.path().join("new").exists(), "checked before anything was created");
    }

    #[test]
    fn a_run_that_never_starts_takes_back_what_it_made() {
        let t = tempfile::tempdir().unwrap();
        let empty = t.path().join("empty");
        std::fs::create_dir(&empty).unwrap();
        let mut req = RunRequest::new(Target::Explicit(t.path().join("a/b/out")));
        req.also.push(("--record".into(), t.path().join("rec")));
        req.also.push(("--record-right".into(), empty.clone()));
        let mut r = RunDir::create(&req, &start(1, 1)).unwrap();
        std::fs::write(r.join(TELEMETRY_FILE), "").unwrap();
        std::fs::write(t.path().join("rec/telemetry.jsonl"), "").unwrap();
        std::fs::write(empty.join("x.jpg"), "").unwrap();
        r.write_json("summary.json", &serde_json::json!({"frames": 0})).unwrap();
        drop(r);
        let left: Vec<String> = std::fs::read_dir(t.path())
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(left, ["empty"], "only the folder that was there, empty again");
        assert_eq!(std::fs::read_dir(&empty).unwrap().count(), 0);
        // Under a default parent: the parent made for it goes too, a shared one stays.
        let parent = t.path().join("out/sim");
        drop(RunDir::create(&RunRequest::new(Target::Under(parent.clone())), &start(1, 1)).unwrap());
        assert!(!t.path().join("out").exists());
        let mut kept = RunDir::create(&RunRequest::new(Target::Under(parent.clone())), &start(1, 1)).unwrap();
        kept.started().unwrap();
        drop(RunDir::create(&RunRequest::new(Target::Under(parent.clone())), &start(1, 2)).unwrap());
        assert_eq!(
            std::fs::read_dir(&parent).unwrap().count(),
            2,
            "the started run and latest"
        );
    }

    #[test]
    fn an_output_inside_what_the_run_reads_is_refused() {
        let t = tempfile::tempdir().unwrap();
        let rec = t.path().join("rec");
        std::fs::create_dir_all(rec.join("seg_000000")).unwrap();
        for (out, how) in [
            (rec.join("replay"), "inside"),
            (rec.join("seg_000000/../x"), "inside"),
            (rec.clone(), "the same folder as"),
        ] {
            let mut req = RunRequest::new(Target::Explicit(out.clone()));
            req.reads.push(("DIR".into(), rec.clone()));
            let e = RunDir::create(&req, &start(1, 1)).unwrap_err().to_string();
            assert!(e.contains(&format!("is {how} DIR {}", rec.display())), "{e}");
        }
        let mut req = RunRequest::new(Target::Under(rec.clone()));
        req.reads.push(("DIR".into(), rec.clone()));
        assert!(matches!(
            RunDir::create(&req, &start(1, 1)),
            Err(RunDirError::InsideInput { .. })
        ));
        assert!(!rec.join("replay").exists() && !rec.join("x").exists());
        // Beside it is fine.
        let mut req = RunRequest::new(Target::Explicit(t.path().join("rec2")));
        req.reads.push(("DIR".into(), rec.clone()));
        RunDir::create(&req, &start(1, 1)).unwrap();
    }

    #[test]
    fn summaries_are_written_whole_with_the_run_id() {
        let t = tempfile::tempdir().unwrap();
        let mut r = RunDir::create(
            &RunRequest::new(Target::Explicit(t.path().join("o"))),
            &start(1_795_185_012, 7),
        )
        .unwrap();
        #[derive(Serialize)]
        struct S {
            zeta: u32,
            alpha: f64,
        }
        r.write_json("summary.json", &S { zeta: 1, alpha: 0.5 }).unwrap();
        let text = std::fs::read_to_string(r.join("summary.json")).unwrap();
        // The run id first, then the fields in their order.
        assert_eq!(
            text,
            "{\n  \"run_id\": \"20261120-153012-7\",\n  \"zeta\": 1,\n  \"alpha\": 0.5\n}\n"
        );
        r.write("sweep.csv", b"a,b\n").unwrap();
        r.finish(RunEnd {
            state: RunState::Interrupted,
            telemetry_frames: None,
        })
        .unwrap();
        let rec = read_record(&r.join(RUN_FILE)).unwrap();
        assert_eq!(rec.files, ["summary.json", "sweep.csv"]);
        assert_eq!(rec.state, RunState::Interrupted);
        // No temporary file left beside them.
        assert_eq!(std::fs::read_dir(r.path()).unwrap().count(), 3);
        // A file that cannot be written is named.
        std::fs::create_dir(r.join("busy.json")).unwrap();
        let e = r.write_json("busy.json", &1).unwrap_err().to_string();
        assert!(e.contains("busy.json: cannot write"), "{e}");
    }

    fn finished_run(dir: &Path, frames: u64, pid: u32) -> RunDir {
        let mut r = RunDir::create(
            &RunRequest::new(Target::Explicit(dir.to_path_buf())),
            &start(1_795_185_012, pid),
        )
        .unwrap();
        r.started().unwrap();
        std::fs::write(r.join(TELEMETRY_FILE), "{}\n".repeat(frames as usize)).unwrap();
        r.write_json("summary.json", &serde_json::json!({"frames": frames}))
            .unwrap();
        r.write_json("config.json", &serde_json::json!({"steering": {"kp": 1.0}}))
            .unwrap();
        r.write("path.png", b"png").unwrap();
        r.finish(RunEnd {
            state: RunState::Finished,
            telemetry_frames: Some(frames),
        })
        .unwrap();
        r
    }

    #[test]
    fn check_run_finds_files_of_two_runs() {
        let t = tempfile::tempdir().unwrap();
        let (a, b) = (t.path().join("a"), t.path().join("b"));
        finished_run(&a, 15, 1);
        finished_run(&b, 30, 2);
        let c = check_run(&a).unwrap();
        assert!(
            c.problems.is_empty() && c.notes.is_empty() && c.foreign.is_empty(),
            "{c:?}"
        );
        // b's telemetry in a.
        std::fs::copy(b.join(TELEMETRY_FILE), a.join(TELEMETRY_FILE)).unwrap();
        let c = check_run(&a).unwrap();
        assert_eq!(
            c.problems,
            [
                "telemetry.jsonl has 30 frames, summary.json says the run had 15",
                "telemetry.jsonl has 30 frames, run.json says run 20261120-153012-1 wrote 15"
            ]
        );
        // b's config in a.
        finished_run(&t.path().join("c"), 15, 3);
        std::fs::copy(b.join("config.json"), t.path().join("c/config.json")).unwrap();
        let c = check_run(&t.path().join("c")).unwrap();
        assert_eq!(
            c.problems,
            ["config.json is run 20261120-153012-2's, run.json is run 20261120-153012-3's"]
        );
        // A plot of another run: foreign, not a problem.
        let d = t.path().join("d");
        finished_run(&d, 5, 4);
        std::fs::write(d.join("old.png"), "png").unwrap();
        let c = check_run(&d).unwrap();
        assert!(c.problems.is_empty(), "{c:?}");
        assert!(c.is_foreign("old.png") && !c.is_foreign("path.png"));
    }

    #[test]
    fn check_run_of_an_older_folder_checks_the_counts() {
        let t = tempfile::tempdir().unwrap();
        std::fs::write(t.path().join("summary.json"), r#"{"frames": 28}"#).unwrap();
        std::fs::write(t.path().join(TELEMETRY_FILE), "").unwrap();
        let c = check_run(t.path()).unwrap();
        assert_eq!(
            c.problems,
            ["telemetry.jsonl has 0 frames, summary.json says the run had 28"]
        );
        assert_eq!(c.notes.len(), 1);
        assert!(c.notes[0].contains("no run.json"), "{:?}", c.notes);
        std::fs::write(t.path().join(TELEMETRY_FILE), "{}\n".repeat(28)).unwrap();
        assert!(check_run(t.path()).unwrap().problems.is_empty());
    }

    #[test]
    fn lines_are_counted_with_a_cut_last_line() {
        let t = tempfile::tempdir().unwrap();
        let p = t.path().join("f");
        for (text, n) in [("", 0), ("a\n", 1), ("a\nb", 2), ("a\n\nb\n", 3)] {
            std::fs::write(&p, text).unwrap();
            assert_eq!(count_lines(&p).unwrap(), n, "{text:?}");
        }
    }
}
