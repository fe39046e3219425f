//! The Raspberry Pi camera module through `rpicam-vid` (Raspberry Pi OS Bookworm and later;
//! `libcamera-vid` on Bullseye): `--camera picam:N` runs
//!
//! ```text
//! rpicam-vid --camera N --nopreview --timeout 0 --width W --height H --framerate FPS
//!            --codec yuv420 --flush --output -
//!            [--shutter US --gain G] [--awbgains R,B]
//! ```
//!
//! and reads its stdout (`picam:N:mjpeg`: `--codec mjpeg --quality 90` instead). Every option
//! is from Raspberry Pi's documentation of the rpicam-apps (camera software, "rpicam-vid",
//! "Common options", "Video options"): `--timeout 0` runs until stopped, `--output -` writes
//! to stdout, `--flush` flushes each frame at once (no stdio buffering between the camera and
//! rccar), `--shutter`/`--gain` fix the exposure, non-zero `--awbgains` switch the automatic
//! white balance off. `--camera` is left out for camera 0 (older `libcamera-vid` builds lack
//! it).
//!
//! The frame layout, from rpicam-apps' source (`--codec yuv420` is its "null encoder": each
//! camera buffer written as it is):
//! - planar YUV 4:2:0 in the JPEG colour space (`FLAG_VIDEO_JPEG_COLOURSPACE` for the yuv420
//!   and mjpeg codecs: BT.601, full range 0..255) → [`RawFormat::Yuv420`] `full_range`;
//! - luma rows padded to a multiple of 64 bytes on the Pi 4's ISP (Raspberry Pi's kernel,
//!   "isp: Set the YUV420/YVU420 format stride to 64 bytes"; rpicam-apps issue 151: 4056 wide
//!   gives 4096-byte rows), chroma rows half that. The shipped 320×240 is a multiple of 64:
//!   no padding. **Unverified on a real Pi here** (no camera on the build machine): the
//!   argument building and the frame parsing are unit-tested on frames made to this layout.
//!
//! [`list_cameras`] reads `rpicam-vid --list-cameras` (for `rccar camera check`).

use super::format::RawFormat;
use super::PipeCommand;
use crate::config::CameraConfig;
use std::path::PathBuf;

/// The capture programs, newest name first.
pub const PROGRAMS: [&str; 2] = ["rpicam-vid", "libcamera-vid"];

/// The first of [`PROGRAMS`] on `PATH`.
pub fn find_program() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    PROGRAMS
        .iter()
        .find_map(|p| std::env::split_paths(&path).map(|d| d.join(p)).find(|f| f.is_file()))
}

/// Which stream rpicam-vid writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Codec {
    /// Raw YUV 4:2:0 (no encoding on the Pi; the default).
    Yuv420,
    /// Motion JPEG at quality 90 (fewer bytes; the JPEG decode costs rccar a little).
    Mjpeg,
}

/// What `picam:N[:mjpeg]` asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Picam {
    /// Camera index (`rpicam-vid --list-cameras`).
    pub index: u32,
    /// The stream.
    pub codec: Codec,
}

/// Row bytes of rpicam-vid's YUV420 luma plane at `width` (a multiple of 64; see the module
/// notes).
pub fn yuv420_stride(width: u32) -> u32 {
    width.div_ceil(64) * 64
}

/// The arguments after the program name (see the module notes).
pub fn args(cam: &Picam, c: &CameraConfig) -> Vec<String> {
    let mut a: Vec<String> = Vec::new();
    let mut push = |k: &str, v: Option<String>| {
        a.push(k.into());
        a.extend(v);
    };
    if cam.index != 0 {
        push("--camera", Some(cam.index.to_string()));
    }
    push("--nopreview", None);
    push("--timeout", Some("0".into()));
    push("--width", Some(c.width.to_string()));
    push("--height", Some(c.height.to_string()));
    push("--framerate", Some(fmt_num(c.fps)));
    match cam.codec {
        Codec::Yuv420 => push("--codec", Some("yuv420".into())),
        Codec::Mjpeg => {
            push("--codec", Some("mjpeg".into()));
            push("--quality", Some("90".into()));
        }
    }
    push("--flush", None);
    push("--output", Some("-".into()));
    if c.shutter_us > 0 {
        push("--shutter", Some(c.shutter_us.to_string()));
    }
    if c.gain > 0.0 {
        push("--gain", Some(fmt_num(c.gain)));
    }
    if c.awb_gains[0] > 0.0 && c.awb_gains[1] > 0.0 {
        push(
            "--awbgains",
            Some(format!("{},{}", fmt_num(c.awb_gains[0]), fmt_num(c.awb_gains[1]))),
        );
    }
    a
}

/// A number as rpicam-vid reads it: no trailing `.0`.
fn fmt_num(v: f64) -> String {
    if v.fract() == 0.0 {
        format!("{v:.0}")
    } else {
        format!("{v}")
    }
}

/// The command for `cam` run by `program`, and how to read it.
pub fn command(program: &str, cam: &Picam, c: &CameraConfig) -> PipeCommand {
    let mut argv = vec![program.to_string()];
    argv.extend(args(cam, c));
    PipeCommand {
        argv,
        format: match cam.codec {
            Codec::Yuv420 => RawFormat::Yuv420 {
                full_range: true,
                stride: yuv420_stride(c.width),
            },
            Codec::Mjpeg => RawFormat::Mjpeg,
        },
        label: format!("picam:{}", cam.index),
    }
}

/// One camera of `rpicam-vid --list-cameras`.
#[derive(Debug, Clone, PartialEq)]
pub struct Listed {
    /// Its index (`--camera N`, `picam:N`).
    pub index: u32,
    /// The sensor (imx219 = camera v2, imx708 = camera 3, imx477 = HQ).
    pub sensor: String,
    /// Its full resolution.
    pub full_size: (u32, u32),
    /// The smallest and largest modes, with their fps (`640x480 [206.65 fps ...]`).
    pub modes: Vec<(u32, u32, f64)>,
}

/// Reads `rpicam-vid --list-cameras` output: `N : sensor [WxH] (path)` lines, each followed
/// by its modes (`WxH [F fps - …]`). Lines it does not know are skipped.
pub fn parse_list(text: &str) -> Vec<Listed> {
    let mut out: Vec<Listed> = Vec::new();
    for line in text.lines() {
        let t = line.trim();
        if let Some((idx, rest)) = t.split_once(" : ") {
            if let Ok(index) = idx.trim().parse::<u32>() {
                let sensor = rest.split_whitespace().next().unwrap_or("").to_string();
                let full_size = bracket(rest).and_then(size_of).unwrap_or((0, 0));
                out.push(Listed {
                    index,
                    sensor,
                    full_size,
                    modes: Vec::new(),
                });
            }
        }
        // a mode: "... 640x480 [206.65 fps - (1000, 752)/1280x960 crop]"
        if let (Some(cam), Some(open)) = (out.last_mut(), t.find(" [")) {
            if t.contains(" fps") {
                let size = t[..open].split_whitespace().last().and_then(size_of);
                let fps = t[open + 2..]
                    .split_whitespace()
                    .next()
                    .and_then(|f| f.parse::<f64>().ok());
                if let (Some((w, h)), Some(fps)) = (size, fps) {
                    cam.modes.push((w, h, fps));
                }
            }
        }
    }
    out
}

fn bracket(s: &str) -> Option<&str> {
    let a = s.find('[')?;
    let b = s[a..].find(']')?;
    Some(&s[a + 1..a + b])
}

fn size_of(s: &str) -> Option<(u32, u32)> {
    let (w, h) = s.trim().split_once('x')?;
    Some((w.parse().ok()?, h.parse().ok()?))
}

/// Runs `PROGRAM --list-cameras` (bounded: 10 s, its output capped at 64 KiB).
pub fn list_cameras(program: &std::path::Path) -> Result<(Vec<Listed>, String), String> {
    use std::io::Read;
    let mut child = std::process::Command::new(program)
        .arg("--list-cameras")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .map_err(|e| format!("{}: {e}", program.display()))?;
    let out = child.stdout.take();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(o) = out {
            let _ = o.take(64 * 1024).read_to_string(&mut s);
        }
        s
    });
    let t0 = std::time::Instant::now();
    while child.try_wait().ok().flatten().is_none() {
        if t0.elapsed() > std::time::Duration::from_secs(10) {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("{} --list-cameras: no answer in 10 s", program.display()));
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let text = reader.join().unwrap_or_default();
    Ok((parse_list(&text), text))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipecam::format::{FrameReader, Item};

    fn cfg() -> CameraConfig {
        CameraConfig::default()
    }

    #[test]
    fn the_default_command_line() {
        let cmd = command(
            "rpicam-vid",
            &Picam {
                index: 0,
                codec: Codec::Yuv420,
            },
            &cfg(),
        );
        assert_eq!(
            cmd.line(),
            "rpicam-vid --nopreview --timeout 0 --width 320 --height 240 --framerate 30 --codec yuv420 --flush --output -"
        );
        assert_eq!(
            cmd.format,
            RawFormat::Yuv420 {
                full_range: true,
                stride: 320
            }
        );
        assert_eq!(cmd.label, "picam:0");
    }

    #[test]
    fn fixed_exposure_white_balance_camera_and_mjpeg() {
        let mut c = cfg();
        c.shutter_us = 8000;
        c.gain = 2.5;
        c.awb_gains = [1.6, 2.0];
        c.fps = 20.0;
        let cmd = command(
            "libcamera-vid",
            &Picam {
                index: 1,
                codec: Codec::Mjpeg,
            },
            &c,
        );
        assert_eq!(
            cmd.argv.join(" "),
            "libcamera-vid --camera 1 --nopreview --timeout 0 --width 320 --height 240 --framerate 20 \
             --codec mjpeg --quality 90 --flush --output - --shutter 8000 --gain 2.5 --awbgains 1.6,2"
        );
        assert_eq!(cmd.format, RawFormat::Mjpeg);
        // one gain of the pair at 0: automatic white balance (no --awbgains)
        c.awb_gains = [1.6, 0.0];
        assert!(!args(
            &Picam {
                index: 0,
                codec: Codec::Yuv420
            },
            &c
        )
        .contains(&"--awbgains".to_string()));
    }

    #[test]
    fn strides_pad_to_64_bytes() {
        assert_eq!(yuv420_stride(320), 320);
        assert_eq!(yuv420_stride(640), 640);
        assert_eq!(yuv420_stride(4056), 4096);
        assert_eq!(yuv420_stride(200), 256);
    }

    /// Two frames as rpicam-vid's yuv420 codec writes them at 200×4 (rows padded to 256
    /// bytes, garbage in the padding): the padding never shows, the full-range levels are
    /// kept as they are.
    #[test]
    fn padded_yuv420_frames_read_back() {
        let mut c = cfg();
        c.width = 200;
        c.height = 4;
        let cmd = command(
            "rpicam-vid",
            &Picam {
                index: 0,
                codec: Codec::Yuv420,
            },
            &c,
        );
        let (w, h, s) = (200usize, 4usize, 256usize);
        let frame = |k: u8| {
            let mut b = Vec::new();
            for y in 0..h {
                for x in 0..s {
                    b.push(if x < w {
                        (x as u8).wrapping_add(k).wrapping_add(y as u8)
                    } else {
                        0xEE
                    });
                }
            }
            for _ in 0..2 {
                for _y in 0..h / 2 {
                    for x in 0..s / 2 {
                        b.push(if x < w / 2 { 128 } else { 0x11 });
                    }
                }
            }
            b
        };
        let mut stream = frame(0);
        stream.extend(frame(9));
        assert_eq!(cmd.format.frame_bytes(200, 4), Some(stream.len() / 2));
        let mut r = FrameReader::new(&stream[..], cmd.format, 200, 4);
        for k in [0u8, 9] {
            match r.next_item().unwrap() {
                Item::Frame(img) => {
                    assert_eq!(img.dimensions(), (200, 4));
                    for (x, y, p) in img.enumerate_pixels() {
                        let want = (x as u8).wrapping_add(k).wrapping_add(y as u8);
                        assert_eq!(p.0, [want; 3], "({x},{y}) of frame {k}");
                    }
                }
                i => panic!("{i:?}"),
            }
        }
        assert!(matches!(r.next_item().unwrap(), Item::End));
    }

    /// The list of Raspberry Pi's documentation ("Common options", `list-cameras`).
    #[test]
    fn the_documented_camera_list_parses() {
        let text = "Available cameras
-----------------
0 : imx219 [3280x2464] (/base/soc/i2c0mux/i2c@1/imx219@10)
    Modes: 'SRGGB10_CSI2P' : 640x480 [206.65 fps - (1000, 752)/1280x960 crop]
                             1640x1232 [41.85 fps - (0, 0)/3280x2464 crop]
                             1920x1080 [47.57 fps - (680, 692)/1920x1080 crop]
                             3280x2464 [21.19 fps - (0, 0)/3280x2464 crop]
           'SRGGB8' : 640x480 [206.65 fps - (1000, 752)/1280x960 crop]
1 : imx477 [4056x3040] (/base/soc/i2c0mux/i2c@1/imx477@1a)
    Modes: 'SRGGB10_CSI2P' : 1332x990 [120.05 fps - (696, 528)/2664x1980 crop]
           'SRGGB12_CSI2P' : 2028x1080 [50.03 fps - (0, 440)/4056x2160 crop]
";
        let l = parse_list(text);
        assert_eq!(l.len(), 2);
        assert_eq!(
            (l[0].index, l[0].sensor.as_str(), l[0].full_size),
            (0, "imx219", (3280, 2464))
        );
        assert_eq!(l[0].modes.len(), 5);
        assert_eq!(l[0].modes[0], (640, 480, 206.65));
        assert_eq!(
            (l[1].index, l[1].sensor.as_str(), l[1].full_size),
            (1, "imx477", (4056, 3040))
        );
        assert_eq!(l[1].modes[1], (2028, 1080, 50.03));
        assert!(parse_list("No cameras available!").is_empty());
    }
}
