//! `rccar report DIR`: one page a student hands in for a run. DIR is an output folder of
//! `rccar sim` or `rccar replay` (summary.json, telemetry.jsonl, config.json, the PNG plots);
//! writes `DIR/report.md` (images linked beside it) and `DIR/report.html` (self-contained:
//! the images base64-embedded, so it survives e-mail).
//!
//! Contents: the run (run.json), the configuration keys that differ from the defaults
//! (`config.json`, written by `rccar sim`), the summary figures with units (and the step
//! response when there is one), figures from the telemetry (frames, lane lost, RMS of the lane
//! error, RMS of the frame-to-frame steering change), and every plot of the run in DIR.
//!
//! One run only ([`rccar::run_dir::check_run`]): files of different runs side by side (run ids
//! that disagree, a telemetry with more or fewer frames than the run wrote) are refused, each
//! mismatch named (`--force` writes the report anyway, the warning on top); a plot the run
//! did not write is left out and named. DIR may also be a folder of runs (`out/sim`): its
//! `latest` is reported.

use anyhow::{bail, Context, Result};
use clap::Args;
use rccar::config::Config;
use serde_json::Value;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Flags of `rccar report`.
#[derive(Args, Debug)]
pub struct ReportArgs {
    /// A run's output folder (e.g. out/sim/latest), holding summary.json and/or
    /// telemetry.jsonl; or a folder of runs (out/sim), whose newest run (latest) is reported.
    pub dir: PathBuf,
    /// Title of the report (default: "rccar run: DIR").
    #[arg(long)]
    pub title: Option<String>,
    /// Write the report even when its files are not one run's (the mismatches on top).
    #[arg(long)]
    pub force: bool,
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
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// Every scalar leaf of `v` as (dotted key, value); arrays are kept whole.
fn flatten(v: &Value, prefix: &str, out: &mut Vec<(String, Value)>) {
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                let p = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                flatten(x, &p, out);
            }
        }
        other => out.push((prefix.to_string(), other.clone())),
    }
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
        rccar::sim::sweep::key_unit(key)
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
            let more = if a.len() > 12 { format!(", … ({} in all)", a.len()) } else { String::new() };
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
            (Value::Number(x), Value::Number(y)) => (x.as_f64().unwrap_or(0.0) - y.as_f64().unwrap_or(0.0)).abs() < 1e-12,
            (Value::String(x), Value::String(y)) => x == y || (!x.is_empty() && y.ends_with(&format!("/{x}"))),
            _ => d == v,
        };
        if !same {
            out.push((k, show(&d), show(&v)));
        }
    }
    out
}

/// What the telemetry says: (label, value) rows.
fn telemetry_figures(path: &Path) -> Result<Vec<(String, String)>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))?;
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
    if !bad.is_empty() {
        let shown: Vec<String> = bad.iter().take(5).map(|l| format!("{}:{l}", path.display())).collect();
        eprintln!("report: skipped {} line(s) that are not JSON: {}", bad.len(), shown.join(", "));
    }
    let mut rows = vec![
        ("frames in telemetry".to_string(), n.to_string()),
        ("frames with the lane lost".to_string(), lost.to_string()),
    ];
    if ne > 0 {
        rows.push(("lane error RMS (normalised, −1..1)".into(), format!("{:.4}", (sq / ne as f64).sqrt())));
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
    Ok(rows)
}

/// The plots in DIR (those of `check` that are not the run's left out), in a fixed order
/// (the run's plots first), at most 20.
fn plots(dir: &Path, check: &rccar::run_dir::RunCheck) -> Result<Vec<PathBuf>> {
    const ORDER: [&str; 6] = ["xte_steer.png", "path.png", "step.png", "sweep.png", "sweep_grid.png", "plot.png"];
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("{}: cannot read", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .filter(|p| !p.file_name().is_some_and(|n| n.to_string_lossy().starts_with("frame_")))
        .filter(|p| !p.file_name().is_some_and(|n| check.is_foreign(&n.to_string_lossy())))
        .collect();
    let rank = |p: &PathBuf| {
        let n = p.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
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
struct Section {
    title: String,
    head: Vec<&'static str>,
    rows: Vec<Vec<String>>,
    note: Option<String>,
}

/// Runs `rccar report`.
pub fn run(a: ReportArgs) -> Result<ExitCode> {
    let mut dir = a.dir.clone();
    if !dir.is_dir() {
        bail!(
            "{}: not a folder (give a run's output folder, e.g. out/sim/latest)",
            dir.display()
        );
    }
    let is_run = |d: &Path| {
        ["summary.json", "telemetry.jsonl", rccar::run_dir::RUN_FILE]
            .iter()
            .any(|f| d.join(f).is_file())
    };
    let latest = dir.join(rccar::run_dir::LATEST);
    if !is_run(&dir) && latest.is_dir() {
        let target = std::fs::read_link(&latest).map_or_else(|_| latest.clone(), |t| dir.join(t));
        println!(
            "report: {} is a folder of runs; reporting the newest, {}",
            dir.display(),
            target.display()
        );
        dir = target;
    }
    let dir = &dir;
    let sum_path = dir.join("summary.json");
    let tel_path = dir.join("telemetry.jsonl");
    if !sum_path.is_file() && !tel_path.is_file() {
        bail!(
            "{}: neither summary.json nor telemetry.jsonl here; run `rccar sim --out {0}` or `rccar replay FRAMES --out {0}` first",
            dir.display()
        );
    }
    // One run's files, or nothing (unless --force).
    let check = rccar::run_dir::check_run(dir)?;
    for n in &check.notes {
        eprintln!("report: note: {n}");
    }
    for f in &check.foreign {
        eprintln!(
            "report: left out {}: not written by this run (not in {})",
            dir.join(f).display(),
            rccar::run_dir::RUN_FILE
        );
    }
    if !check.problems.is_empty() {
        if !a.force {
            bail!(
                "{}: these files are not one run's: {}; report one run's folder (each run writes a new one), or give --force to write the report anyway with this warning on top",
                dir.display(),
                check.problems.join("; ")
            );
        }
        eprintln!(
            "report: WARNING: {}: these files are not one run's: {}",
            dir.display(),
            check.problems.join("; ")
        );
    }
    let mut sections = Vec::new();
    if !check.problems.is_empty() {
        sections.push(Section {
            title: "Warning: these files do not belong to one run".into(),
            head: vec!["mismatch"],
            rows: check.problems.iter().map(|p| vec![p.clone()]).collect(),
            note: Some("The figures below mix runs (written with --force).".into()),
        });
    }
    if let Some(r) = &check.record {
        sections.push(Section {
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
        });
    }
    let cfg_path = dir.join("config.json");
    if cfg_path.is_file() {
        let text = std::fs::read_to_string(&cfg_path).with_context(|| format!("{}: cannot read", cfg_path.display()))?;
        let v: Value = serde_json::from_str(&text).with_context(|| format!("{}: not JSON", cfg_path.display()))?;
        let d = config_diff(&v);
        sections.push(Section {
            title: "Configuration: what differs from the defaults".into(),
            head: vec!["key", "default", "this run", "unit"],
            note: d.is_empty().then(|| "Every key has its default value (config/car.toml as shipped).".to_string()),
            rows: d.into_iter().map(|(k, x, y)| {
                let u = unit(&k).to_string();
                vec![k, x, y, u]
            }).collect(),
        });
    } else {
        sections.push(Section {
            title: "Configuration".into(),
            head: vec![],
            rows: vec![],
            note: Some("No config.json in this folder (`rccar sim` writes one); differences unknown.".into()),
        });
    }
    if sum_path.is_file() {
        let text = std::fs::read_to_string(&sum_path).with_context(|| format!("{}: cannot read", sum_path.display()))?;
        let v: Value = serde_json::from_str(&text).with_context(|| format!("{}: not JSON", sum_path.display()))?;
        let mut flat = Vec::new();
        flatten(&v, "", &mut flat);
        flat.retain(|(k, _)| k != "run_id");
        let (step, main): (Vec<_>, Vec<_>) = flat.into_iter().partition(|(k, _)| k.starts_with("step."));
        let main = ordered(
            main,
            &[
                "track", "xte_rms_m", "xte_max_m", "lane_departures", "time_outside_s", "laps", "lap_times_s",
                "steer_reversals_per_s", "lane_lost_frames", "frames", "seconds", "end",
            ],
        );
        let step = ordered(
            step,
            &["step.initial_offset_m", "step.t0_s", "step.rise_time_s", "step.overshoot_pct", "step.settling_time_s", "step.band_m"],
        );
        sections.push(Section {
            title: "Summary".into(),
            head: vec!["figure", "value", "unit"],
            rows: main.iter().map(|(k, v)| vec![k.clone(), show(v), unit(k).to_string()]).collect(),
            note: None,
        });
        if !step.is_empty() {
            sections.push(Section {
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
    }
    if tel_path.is_file() {
        sections.push(Section {
            title: "From the telemetry".into(),
            head: vec!["figure", "value"],
            rows: telemetry_figures(&tel_path)?.into_iter().map(|(k, v)| vec![k, v]).collect(),
            note: None,
        });
    }
    let pngs = plots(dir, &check)?;
    let title = a.title.clone().unwrap_or_else(|| format!("rccar run: {}", dir.display()));

    // Markdown, images beside it.
    let mut md = format!("# {title}\n\n");
    for s in &sections {
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
    if !pngs.is_empty() {
        md += "## Plots\n\n";
        for p in &pngs {
            let n = p.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
            let _ = writeln!(md, "### {n}\n\n![{n}]({n})\n");
        }
    }

    // HTML, self-contained.
    let mut html = format!(
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>{t}</title>\n<style>body{{font-family:sans-serif;max-width:1050px;margin:2em auto;color:#222}}table{{border-collapse:collapse;margin:0.5em 0}}td,th{{border:1px solid #bbb;padding:3px 8px;text-align:left}}th{{background:#eee}}td:nth-child(2),td:nth-child(3){{font-family:monospace}}img{{max-width:100%;border:1px solid #ccc}}</style>\n</head><body>\n<h1>{t}</h1>\n",
        t = html_escape(&title)
    );
    for s in &sections {
        let _ = writeln!(html, "<h2>{}</h2>", html_escape(&s.title));
        if !s.head.is_empty() && !s.rows.is_empty() {
            html += "<table><tr>";
            for h in &s.head {
                let _ = write!(html, "<th>{}</th>", html_escape(h));
            }
            html += "</tr>\n";
            for r in &s.rows {
                html += "<tr>";
                for c in r {
                    let _ = write!(html, "<td>{}</td>", html_escape(c));
                }
                html += "</tr>\n";
            }
            html += "</table>\n";
        }
        if let Some(n) = &s.note {
            let _ = writeln!(html, "<p>{}</p>", html_escape(n));
        }
    }
    if !pngs.is_empty() {
        html += "<h2>Plots</h2>\n";
        for p in &pngs {
            let bytes = std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?;
            let n = p.file_name().map(|n| n.to_string_lossy().to_string()).unwrap_or_default();
            let _ = writeln!(
                html,
                "<h3>{0}</h3>\n<img alt=\"{0}\" src=\"data:image/png;base64,{1}\">",
                html_escape(&n),
                base64(&bytes)
            );
        }
    }
    html += "</body></html>\n";
    let (md_path, html_path) = (dir.join("report.md"), dir.join("report.html"));
    std::fs::write(&md_path, md).with_context(|| format!("{}: cannot write", md_path.display()))?;
    std::fs::write(&html_path, &html).with_context(|| format!("{}: cannot write", html_path.display()))?;
    println!(
        "report: {} and {} ({} plot(s) embedded, {} KB)",
        md_path.display(),
        html_path.display(),
        pngs.len(),
        html.len() / 1024
    );
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (i, o) in [("", ""), ("f", "Zg=="), ("fo", "Zm8="), ("foo", "Zm9v"), ("foob", "Zm9vYg=="), ("fooba", "Zm9vYmE="), ("foobar", "Zm9vYmFy")] {
            assert_eq!(base64(i.as_bytes()), o);
        }
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
