//! The report a student hands in for a run (`rccar report DIR`): its sections computed from a
//! run folder's files (run.json, config.json, summary.json, telemetry.jsonl, the PNG plots),
//! as Markdown (images linked beside it) and as self-contained HTML (the images
//! base64-embedded, so it survives e-mail).
//!
//! [`Report::load`] is the loader (it reads the folder; which files belong to the run is
//! [`crate::run_dir::check_run`]'s answer, passed in) and [`Report::write`] the writer; the
//! rendering between them touches no file. The binary picks the folder, prints and exits.

use crate::config::Config;
use crate::run_dir::RunCheck;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A file of the report that cannot be read, parsed or written.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The file or folder cannot be read.
    #[error("{}: cannot read", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// The file is not JSON.
    #[error("{}: not JSON", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// Where and why.
        #[source]
        source: serde_json::Error,
    },
    /// The report cannot be written.
    #[error("{}: cannot write", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
}

fn read_text(path: &Path) -> Result<String, ReportError> {
    std::fs::read_to_string(path).map_err(|source| ReportError::Read {
        path: path.to_path_buf(),
        source,
    })
}

fn read_json(path: &Path) -> Result<Value, ReportError> {
    serde_json::from_str(&read_text(path)?).map_err(|source| ReportError::Json {
        path: path.to_path_buf(),
        source,
    })
}

/// Standard base64 (RFC 4648) of `bytes`, with padding.
pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn html_escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Every scalar leaf of `v` as (dotted key, value); arrays are kept whole.
fn flatten(v: &Value, prefix: &str, out: &mut Vec<(String, Value)>) {
    crate::fields::for_each_leaf(v, prefix, &mut |p, leaf| out.push((p.to_string(), leaf.clone())));
}

/// The unit of a summary or config key, from its name.
fn unit(key: &str) -> &'static str {
    let last = key.rsplit('.').next().unwrap_or(key);
    if last == "seconds" || last.ends_with("_seconds") {
        "s"
    } else if last.ends_with("_pct") {
        "%"
    } else if last.ends_with("_per_s") {
        "1/s"
    } else if last.ends_with("_mps") {
        "m/s"
    } else if last.ends_with("_deg") {
        "deg"
    } else if last.ends_with("_px") {
        "px"
    } else if last.ends_with("_m") {
        "m"
    } else if last.ends_with("_s") {
        "s"
    } else {
        crate::sim::sweep::key_unit(key)
    }
}

fn show(v: &Value) -> String {
    match v {
        Value::Number(n) => match n.as_f64() {
            Some(f) if n.is_f64() => {
                if f != 0.0 && (f.abs() < 1e-3 || f.abs() >= 1e6) {
                    format!("{f:.4e}")
                } else {
                    let s = format!("{f:.4}");
                    s.trim_end_matches('0').trim_end_matches('.').to_string()
                }
            }
            _ => n.to_string(),
        },
        Value::String(s) => s.clone(),
        Value::Null => "—".into(),
        Value::Array(a) => {
            let items: Vec<String> = a.iter().take(12).map(show).collect();
            let more = if a.len() > 12 {
                format!(", … ({} in all)", a.len())
            } else {
                String::new()
            };
            format!("[{}{more}]", items.join(", "))
        }
        other => other.to_string(),
    }
}

/// Config keys whose value differs from [`Config::default`]: (key, default, this run's).
/// A path that only became absolute (the loader resolves them) is not a difference.
fn config_diff(run: &Value) -> Vec<(String, String, String)> {
    let Ok(def) = serde_json::to_value(Config::default()) else {
        return Vec::new();
    };
    let (mut a, mut b) = (Vec::new(), Vec::new());
    flatten(&def, "", &mut a);
    flatten(run, "", &mut b);
    b.retain(|(k, _)| k != "run_id");
    let def: std::collections::BTreeMap<String, Value> = a.into_iter().collect();
    let mut out = Vec::new();
    for (k, v) in b {
        let d = def.get(&k).cloned().unwrap_or(Value::Null);
        let same = match (&d, &v) {
            (Value::Number(x), Value::Number(y)) => {
                (x.as_f64().unwrap_or(0.0) - y.as_f64().unwrap_or(0.0)).abs() < 1e-12
            }
            (Value::String(x), Value::String(y)) => x == y || (!x.is_empty() && y.ends_with(&format!("/{x}"))),
            _ => d == v,
        };
        if !same {
            out.push((k, show(&d), show(&v)));
        }
    }
    out
}

/// (label, value) rows of figures.
pub type Figures = Vec<(String, String)>;

/// What the telemetry says: (label, value) rows, and the numbers of the lines that are not
/// JSON (skipped).
pub fn telemetry_figures(path: &Path) -> Result<(Figures, Vec<usize>), ReportError> {
    let text = read_text(path)?;
    let (mut n, mut lost, mut sq, mut ne, mut dsq, mut nd) = (0u64, 0u64, 0.0, 0u64, 0.0, 0u64);
    let mut last_steer: Option<f64> = None;
    let mut bad = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let Ok(v) = serde_json::from_str::<Value>(line) else {
            bad.push(i + 1);
            continue;
        };
        n += 1;
        match v.get("error").and_then(Value::as_f64) {
            Some(e) => {
                sq += e * e;
                ne += 1;
            }
            None => lost += 1,
        }
        if let Some(s) = v.get("steer").and_then(Value::as_f64) {
            if let Some(l) = last_steer {
                dsq += (s - l) * (s - l);
                nd += 1;
            }
            last_steer = Some(s);
        }
    }
    let mut rows = vec![
        ("frames in telemetry".to_string(), n.to_string()),
        ("frames with the lane lost".to_string(), lost.to_string()),
    ];
    if ne > 0 {
        rows.push((
            "lane error RMS (normalised, −1..1)".into(),
            format!("{:.4}", (sq / ne as f64).sqrt()),
        ));
    }
    if nd > 0 {
        rows.push((
            "steering chatter: RMS of the frame-to-frame change".into(),
            format!("{:.4}", (dsq / nd as f64).sqrt()),
        ));
    }
    if !bad.is_empty() {
        rows.push(("telemetry lines skipped (not JSON)".into(), bad.len().to_string()));
    }
    Ok((rows, bad))
}

/// The plots in DIR (those of `check` that are not the run's left out), in a fixed order
/// (the run's plots first), at most 20.
fn plots(dir: &Path, check: &RunCheck) -> Result<Vec<PathBuf>, ReportError> {
    const ORDER: [&str; 6] = [
        "xte_steer.png",
        "path.png",
        "step.png",
        "sweep.png",
        "sweep_grid.png",
        "plot.png",
    ];
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| ReportError::Read {
            path: dir.to_path_buf(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .filter(|p| !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("frame_")))
        .filter(|p| !p.file_name().is_some_and(|n| check.is_foreign(&n.to_string_lossy())))
        .collect();
    let rank = |p: &PathBuf| {
        let n = p
            .file_name()
            .map(|n| n.to_string_lossy().to_string())
            .unwrap_or_default();
        (ORDER.iter().position(|o| *o == n).unwrap_or(ORDER.len()), n)
    };
    v.sort_by_key(rank);
    v.truncate(20);
    Ok(v)
}

/// `flat` with the keys named in `first` moved to the front, in that order.
fn ordered(mut flat: Vec<(String, Value)>, first: &[&str]) -> Vec<(String, Value)> {
    let rank = |k: &str| first.iter().position(|f| *f == k).unwrap_or(first.len());
    flat.sort_by_key(|(k, _)| rank(k));
    flat
}

/// A section: heading and a table of rows.
#[derive(Debug, Clone)]
pub struct Section {
    /// The heading.
    pub title: String,
    /// Column heads (none: no table).
    pub head: Vec<&'static str>,
    /// The table's rows.
    pub rows: Vec<Vec<String>>,
    /// A paragraph under the table.
    pub note: Option<String>,
}

/// A run's report: its title, sections and plots.
pub struct Report {
    /// The title (heading and HTML title).
    pub title: String,
    /// The sections, in order.
    pub sections: Vec<Section>,
    /// The plots: path and PNG bytes, in the report's order.
    pub plots: Vec<(PathBuf, Vec<u8>)>,
    /// Line numbers of telemetry.jsonl that are not JSON (skipped in the figures).
    pub skipped_lines: Vec<usize>,
}

/// The mismatches of files that are not one run's (written with `--force`).
fn warning_section(check: &RunCheck) -> Option<Section> {
    (!check.problems.is_empty()).then(|| Section {
        title: "Warning: these files do not belong to one run".into(),
        head: vec!["mismatch"],
        rows: check.problems.iter().map(|p| vec![p.clone()]).collect(),
        note: Some("The figures below mix runs (written with --force).".into()),
    })
}

/// The run's record (run.json).
fn run_section(check: &RunCheck) -> Option<Section> {
    let r = check.record.as_ref()?;
    Some(Section {
        title: "Run".into(),
        head: vec!["", "value"],
        rows: vec![
            vec!["run id".into(), r.run_id.clone()],
            vec!["command".into(), r.argv.join(" ")],
            vec!["started".into(), r.started.clone()],
            vec![
                "ended".into(),
                serde_json::to_value(r.state)
                    .ok()
                    .and_then(|v| v.as_str().map(String::from))
                    .unwrap_or_default(),
            ],
            vec!["rccar".into(), r.rccar_version.clone()],
        ],
        note: None,
    })
}

/// The configuration keys that differ from the defaults (config.json).
fn config_section(dir: &Path) -> Result<Section, ReportError> {
    let cfg_path = dir.join("config.json");
    if !cfg_path.is_file() {
        return Ok(Section {
            title: "Configuration".into(),
            head: vec![],
            rows: vec![],
            note: Some("No config.json in this folder (`rccar sim` writes one); differences unknown.".into()),
        });
    }
    let d = config_diff(&read_json(&cfg_path)?);
    Ok(Section {
        title: "Configuration: what differs from the defaults".into(),
        head: vec!["key", "default", "this run", "unit"],
        note: d
            .is_empty()
            .then(|| "Every key has its default value (config/car.toml as shipped).".to_string()),
        rows: d
            .into_iter()
            .map(|(k, x, y)| {
                let u = unit(&k).to_string();
                vec![k, x, y, u]
            })
            .collect(),
    })
}

/// The summary's figures and, when there is one, the step response (summary.json).
fn summary_sections(sum_path: &Path) -> Result<Vec<Section>, ReportError> {
    let mut flat = Vec::new();
    flatten(&read_json(sum_path)?, "", &mut flat);
    flat.retain(|(k, _)| k != "run_id");
    let (step, main): (Vec<_>, Vec<_>) = flat.into_iter().partition(|(k, _)| k.starts_with("step."));
    let main = ordered(
        main,
        &[
            "track",
            "xte_rms_m",
            "xte_max_m",
            "lane_departures",
            "time_outside_s",
            "laps",
            "lap_times_s",
            "steer_reversals_per_s",
            "lane_lost_frames",
            "frames",
            "seconds",
            "end",
        ],
    );
    let step = ordered(
        step,
        &[
            "step.initial_offset_m",
            "step.t0_s",
            "step.rise_time_s",
            "step.overshoot_pct",
            "step.settling_time_s",
            "step.band_m",
        ],
    );
    let mut out = vec![Section {
        title: "Summary".into(),
        head: vec!["figure", "value", "unit"],
        rows: main
            .iter()
            .map(|(k, v)| vec![k.clone(), show(v), unit(k).to_string()])
            .collect(),
        note: None,
    }];
    if !step.is_empty() {
        out.push(Section {
            title: "Step response".into(),
            head: vec!["figure", "value", "unit"],
            rows: step
                .iter()
                .map(|(k, v)| {
                    let k = k.trim_start_matches("step.").to_string();
                    let u = unit(&k).to_string();
                    vec![k, show(v), u]
                })
                .collect(),
            note: Some(
                "Rise: 10 → 90 % of the way back to the lane centre. Overshoot: largest excursion past the centre, % of the initial offset. Settling: until |error| stays within the band (5 % of the offset, at least 2 mm).".into(),
            ),
        });
    }
    Ok(out)
}

/// `s`'s table as Markdown, then its note.
fn section_markdown(md: &mut String, s: &Section) {
    let _ = writeln!(md, "## {}\n", s.title);
    if !s.head.is_empty() && !s.rows.is_empty() {
        let _ = writeln!(md, "| {} |", s.head.join(" | "));
        let _ = writeln!(md, "|{}", "---|".repeat(s.head.len()));
        for r in &s.rows {
            let cells: Vec<String> = r.iter().map(|c| c.replace('|', "\\|")).collect();
            let _ = writeln!(md, "| {} |", cells.join(" | "));
        }
        md.push('\n');
    }
    if let Some(n) = &s.note {
        let _ = writeln!(md, "{n}\n");
    }
}

/// `s`'s table as HTML, then its note.
fn section_html(html: &mut String, s: &Section) {
    let _ = writeln!(html, "<h2>{}</h2>", html_escape(&s.title));
    if !s.head.is_empty() && !s.rows.is_empty() {
        *html += "<table><tr>";
        for h in &s.head {
            let _ = write!(html, "<th>{}</th>", html_escape(h));
        }
        *html += "</tr>\n";
        for r in &s.rows {
            *html += "<tr>";
            for c in r {
                let _ = write!(html, "<td>{}</td>", html_escape(c));
            }
            *html += "</tr>\n";
        }
        *html += "</table>\n";
    }
    if let Some(n) = &s.note {
        let _ = writeln!(html, "<p>{}</p>", html_escape(n));
    }
}

/// A file's name as text.
fn name_of(p: &Path) -> String {
    p.file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default()
}

impl Report {
    /// Reads the report of the run in `dir` (`check`: [`crate::run_dir::check_run`]'s answer
    /// for it; its mismatches go on top, its foreign plots are left out).
    pub fn load(dir: &Path, check: &RunCheck, title: String) -> Result<Report, ReportError> {
        let mut sections: Vec<Section> = warning_section(check).into_iter().chain(run_section(check)).collect();
        sections.push(config_section(dir)?);
        let sum_path = dir.join("summary.json");
        if sum_path.is_file() {
            sections.extend(summary_sections(&sum_path)?);
        }
        let tel_path = dir.join("telemetry.jsonl");
        let mut skipped_lines = Vec::new();
        if tel_path.is_file() {
            let (rows, bad) = telemetry_figures(&tel_path)?;
            skipped_lines = bad;
            sections.push(Section {
                title: "From the telemetry".into(),
                head: vec!["figure", "value"],
                rows: rows.into_iter().map(|(k, v)| vec![k, v]).collect(),
                note: None,
            });
        }
        let plots = plots(dir, check)?
            .into_iter()
            .map(|p| match std::fs::read(&p) {
                Ok(b) => Ok((p, b)),
                Err(source) => Err(ReportError::Read { path: p, source }),
            })
            .collect::<Result<_, _>>()?;
        Ok(Report {
            title,
            sections,
            plots,
            skipped_lines,
        })
    }

    /// The report as Markdown, the plots linked by name (they lie beside it).
    pub fn markdown(&self) -> String {
        let mut md = format!("# {}\n\n", self.title);
        for s in &self.sections {
            section_markdown(&mut md, s);
        }
        if !self.plots.is_empty() {
            md += "## Plots\n\n";
            for (p, _) in &self.plots {
                let n = name_of(p);
                let _ = writeln!(md, "### {n}\n\n![{n}]({n})\n");
            }
        }
        md
    }

    /// The report as one self-contained HTML page (the plots embedded).
    pub fn html(&self) -> String {
        let mut html = format!(
            "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\n<style>body{{font-family:sans-serif;max-width:1050px;margin:2em auto;color:#222}}table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:left}}th{{background:#eee}}td:nth-child(2),td:nth-child(3){{font-family:monospace}}img{{max-width:100%;border:1px solid #ccc}}</style>\n</head><body>\n<h1>{t}</h1>\n",
            t = html_escape(&self.title)
        );
        for s in &self.sections {
            section_html(&mut html, s);
        }
        if !self.plots.is_empty() {
            html += "<h2>Plots</h2>\n";
            for (p, bytes) in &self.plots {
                let _ = writeln!(
                    html,
                    "<h3>{0}</h3>\n<img alt=\"{0}\" src=\"data:image/png;base64,{1}\">",
                    html_escape(&name_of(p)),
                    base64(bytes)
                );
            }
        }
        html += "</body></html>\n";
        html
    }

    /// Writes `dir/report.md` and `dir/report.html`; returns their paths and the HTML's size
    /// in bytes.
    pub fn write(&self, dir: &Path) -> Result<(PathBuf, PathBuf, usize), ReportError> {
        let (md_path, html_path) = (dir.join("report.md"), dir.join("report.html"));
        let html = self.html();
        let put = |p: &Path, s: &str| {
            std::fs::write(p, s).map_err(|source| ReportError::Write {
                path: p.to_path_buf(),
                source,
            })
        };
        put(&md_path, &self.markdown())?;
        put(&html_path, &html)?;
        Ok((md_path, html_path, html.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(base64(i.as_bytes()), o);
        }
        assert_eq!(base64(&[0xff, 0xfe, 0x00]), "//4A");
    }

    #[test]
    fn config_diff_names_changed_keys_only() {
        let mut c = Config::default();
        c.steering.kd = 0.2;
        let v = serde_json::to_value(&c).unwrap();
        let d = config_diff(&v);
        assert_eq!(d.len(), 1, "{d:?}");
        assert_eq!(d[0].0, "steering.kd");
        assert_eq!(d[0].2, "0.2");
    }
}
