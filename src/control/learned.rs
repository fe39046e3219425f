//! A learned pilot (issue 29): a small convolutional network that maps the camera frame to
//! the steering command, trained by `rccar-train pilot` (training/src/pilot/, docs/pilot.md)
//! on recordings of the classical controller, and run here on the car's CPU with forward
//! kernels of its own (no inference library on the car).
//!
//! **The network** (one fixed architecture, [`ARCH`]; its shapes are checked on load):
//! 1. **Input.** The frame's rows [`INPUT_TOP`]`..+`[`INPUT_ROWS`] (the floor in front of the
//!    car, the rows the lane pipeline's ROI reads), grey `0.299 R + 0.587 G + 0.114 B`,
//!    averaged over 4×4 blocks and divided by 255: one channel of 18 × 80 values in 0..1.
//! 2. `conv1` 5×5 stride 2, 1 → 8 channels, ReLU (7 × 38);
//!    `conv2` 3×3 stride 2, 8 → 16, ReLU (3 × 18); `conv3` 3×3 stride 1, 16 → 24, ReLU (1 × 16);
//!    no padding anywhere (PyTorch/ONNX `Conv` with `pads = 0`).
//! 3. Flatten in channel, row, column order (ONNX `Flatten` of NCHW), `fc1` 384 → 32, ReLU,
//!    `fc2` 32 → 1: the steering command, −1 (left) ..= 1 (right), before the clamp.
//!
//! 183 k multiply-adds a frame, 17.2 k parameters (69 KB of f32; the file is 70 KB). The kernels keep each
//! activation channels-last (HWC), so one input value meets a contiguous row of output
//! channels and the inner loop vectorises (SSE2 on x86-64, NEON on aarch64) with no
//! intrinsics; the weights are re-ordered once when loaded.
//!
//! **The weights file** is safetensors (a little-endian u64 header length, a JSON header
//! naming each tensor's dtype, shape and byte range, then the raw little-endian f32 data;
//! written and read here without a dependency), so numpy, PyTorch or the ONNX export of the
//! bench read it as they are. Tensors: `conv1.weight` `[8,1,5,5]`, `conv1.bias` `[8]`, …,
//! `fc2.weight` `[1,32]`, `fc2.bias` `[1]` (PyTorch's layouts: convolution `[out,in,kh,kw]`,
//! dense `[out,in]`); `__metadata__` holds `format = rccar-pilot-1`, the frame size and the
//! input crop, and what the trainer says about the run.
//!
//! **Steering**: the network's output clamped to ±`max_steer` and rate-limited to
//! `slew_rate` per second, as the PID's. It reads the frame, not the lane measurement, so a
//! lost lane does not stop it steering (the behaviour machine still decides what a lost lane
//! means); stop signs, lights and obstacles act on top of it as on every method. Time is
//! passed in (`dt`, seconds).

use super::params::{Param, Params};
use super::steering::{limit, Steering, SteeringInput, SteeringMethod, MAX_STEER, SLEW_RATE};
use image::RgbImage;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The `format` the weights file's metadata must name.
pub const FORMAT: &str = "rccar-pilot-1";
/// Frame size the network was made for, pixels (the pipeline's `[camera]` size).
pub const FRAME_W: u32 = 320;
/// Frame height, pixels.
pub const FRAME_H: u32 = 240;
/// First frame row of the input crop.
pub const INPUT_TOP: u32 = 80;
/// Frame rows in the input crop.
pub const INPUT_ROWS: u32 = 72;
/// Side of the square of frame pixels averaged into one input value.
pub const INPUT_SCALE: u32 = 4;
/// Input height, values.
pub const IN_H: usize = (INPUT_ROWS / INPUT_SCALE) as usize;
/// Input width, values.
pub const IN_W: usize = (FRAME_W / INPUT_SCALE) as usize;

/// Weights smaller than this in magnitude are zeros on the car ([`PilotNet::new`]) and in the
/// files the trainer writes. Weight decay shrinks the weights of units that never fire towards
/// zero geometrically, into the subnormal floats, which x86 CPUs compute ~50 times slower
/// (measured: the shipped pilot before this took 0.6 ms of CPU a frame instead of 0.012, and
/// onnxruntime slowed down alike). Below 1e-12 a weight changes the output by < 1e-9.
pub const NEGLIGIBLE: f32 = 1e-12;

/// `w`, or 0 when it is [`NEGLIGIBLE`].
pub fn flush(w: f32) -> f32 {
    if w.abs() < NEGLIGIBLE {
        0.0
    } else {
        w
    }
}

/// One convolution layer: `cin` → `cout` channels, a `k`×`k` kernel moved by `stride`, no
/// padding, ReLU after.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ConvSpec {
    /// Tensor name prefix (`conv1` → `conv1.weight`, `conv1.bias`).
    pub name: &'static str,
    /// Input channels.
    pub cin: usize,
    /// Output channels.
    pub cout: usize,
    /// Kernel side.
    pub k: usize,
    /// Stride.
    pub stride: usize,
}

/// The network's shape: its convolutions, then `fc1` (flattened → `hidden`, ReLU) and `fc2`
/// (`hidden` → 1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Arch {
    /// The convolutions, input first.
    pub convs: [ConvSpec; 3],
    /// Width of the hidden dense layer.
    pub hidden: usize,
}

/// The one architecture (see the module's header).
pub const ARCH: Arch = Arch {
    convs: [
        ConvSpec {
            name: "conv1",
            cin: 1,
            cout: 8,
            k: 5,
            stride: 2,
        },
        ConvSpec {
            name: "conv2",
            cin: 8,
            cout: 16,
            k: 3,
            stride: 2,
        },
        ConvSpec {
            name: "conv3",
            cin: 16,
            cout: 24,
            k: 3,
            stride: 1,
        },
    ],
    hidden: 32,
};

impl Arch {
    /// (height, width) after each convolution, input first: `[(18,80), (7,38), (3,18), (1,16)]`.
    pub fn sizes(&self) -> [(usize, usize); 4] {
        let mut s = [(IN_H, IN_W); 4];
        for (i, c) in self.convs.iter().enumerate() {
            let (h, w) = s[i];
            s[i + 1] = ((h - c.k) / c.stride + 1, (w - c.k) / c.stride + 1);
        }
        s
    }

    /// Length of the flattened last convolution's output (`fc1`'s input).
    pub fn flat(&self) -> usize {
        let (h, w) = self.sizes()[3];
        h * w * self.convs[2].cout
    }

    /// Every tensor's name and shape, in the file's order.
    pub fn tensors(&self) -> Vec<(String, Vec<usize>)> {
        let mut t = Vec::new();
        for c in &self.convs {
            t.push((format!("{}.weight", c.name), vec![c.cout, c.cin, c.k, c.k]));
            t.push((format!("{}.bias", c.name), vec![c.cout]));
        }
        t.push(("fc1.weight".into(), vec![self.hidden, self.flat()]));
        t.push(("fc1.bias".into(), vec![self.hidden]));
        t.push(("fc2.weight".into(), vec![1, self.hidden]));
        t.push(("fc2.bias".into(), vec![1]));
        t
    }

    /// Multiply-adds of one forward pass.
    pub fn macs(&self) -> usize {
        let s = self.sizes();
        let conv: usize = self
            .convs
            .iter()
            .enumerate()
            .map(|(i, c)| s[i + 1].0 * s[i + 1].1 * c.cout * c.cin * c.k * c.k)
            .sum();
        conv + self.flat() * self.hidden + self.hidden
    }
}

/// Why a weights file cannot be used. Every message names the file.
#[derive(Debug, thiserror::Error)]
pub enum PilotError {
    /// The file cannot be read or written.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What the system said.
        error: std::io::Error,
    },
    /// The file is not a pilot's weights file of this architecture.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong (which tensor, which shape).
        message: String,
    },
}

/// The weights of the network, as the file holds them (PyTorch layouts), and its metadata.
#[derive(Debug, Clone, PartialEq)]
pub struct PilotWeights {
    /// Tensor name → values, in the layouts of [`Arch::tensors`].
    pub tensors: BTreeMap<String, Vec<f32>>,
    /// `__metadata__` (the trainer's notes; `format`, frame and crop are added on save).
    pub metadata: BTreeMap<String, String>,
}

impl PilotWeights {
    /// Reads `path` ([`PilotWeights::from_bytes`]).
    pub fn load(path: &Path) -> Result<Self, PilotError> {
        let bytes = std::fs::read(path).map_err(|error| PilotError::Io {
            path: path.to_path_buf(),
            error,
        })?;
        Self::from_bytes(&bytes).map_err(|message| PilotError::Format {
            path: path.to_path_buf(),
            message,
        })
    }

    /// Parses a safetensors file of [`ARCH`]'s tensors, all f32, with `format` =
    /// [`FORMAT`] and the frame size and crop of this build.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, String> {
        let n = bytes
            .get(..8)
            .map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default()))
            .ok_or("not a safetensors file (shorter than its 8-byte header length)")?;
        let end = 8usize
            .checked_add(usize::try_from(n).map_err(|_| "header length too large")?)
            .filter(|&e| e <= bytes.len())
            .ok_or_else(|| format!("not a safetensors file (header of {n} bytes in a file of {})", bytes.len()))?;
        let header: serde_json::Map<String, serde_json::Value> =
            serde_json::from_slice(&bytes[8..end]).map_err(|e| format!("not a safetensors file (header: {e})"))?;
        let data = &bytes[end..];
        let metadata: BTreeMap<String, String> = match header.get("__metadata__") {
            Some(m) => serde_json::from_value(m.clone()).map_err(|e| format!("__metadata__: {e}"))?,
            None => BTreeMap::new(),
        };
        match metadata.get("format") {
            Some(f) if f == FORMAT => {}
            Some(f) => return Err(format!("format {f:?}; this rccar reads {FORMAT:?} (train it again with `rccar-train pilot`)")),
            None => return Err(format!("no `format` in its metadata: not a pilot written by `rccar-train pilot` ({FORMAT})")),
        }
        let want = format!("{FRAME_W}x{FRAME_H}");
        if metadata.get("frame").is_some_and(|f| *f != want) {
            return Err(format!("made for {} frames; this build's pilot reads {want}", metadata["frame"]));
        }
        let mut tensors = BTreeMap::new();
        for (name, shape) in ARCH.tensors() {
            let t = header
                .get(&name)
                .ok_or_else(|| format!("no tensor `{name}` (expected shape {shape:?})"))?;
            let dtype = t.get("dtype").and_then(|d| d.as_str()).unwrap_or("?");
            if dtype != "F32" {
                return Err(format!("`{name}` is {dtype}, expected F32"));
            }
            let got: Vec<usize> = t
                .get("shape")
                .and_then(|s| serde_json::from_value(s.clone()).ok())
                .ok_or_else(|| format!("`{name}`: no shape"))?;
            if got != shape {
                return Err(format!("`{name}` has shape {got:?}, this network's is {shape:?}"));
            }
            let [a, b]: [usize; 2] = t
                .get("data_offsets")
                .and_then(|s| serde_json::from_value(s.clone()).ok())
                .ok_or_else(|| format!("`{name}`: no data_offsets"))?;
            let len: usize = shape.iter().product();
            if b < a || b - a != 4 * len || b > data.len() {
                return Err(format!("`{name}`: data_offsets [{a}, {b}] do not hold {len} f32 in {} bytes of data", data.len()));
            }
            let v: Vec<f32> = data[a..b]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                .collect();
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(format!("`{name}`[{i}] is {} (training diverged?)", v[i]));
            }
            tensors.insert(name, v);
        }
        Ok(Self { tensors, metadata })
    }

    /// The file's bytes: safetensors, tensors in [`Arch::tensors`] order, metadata with
    /// `format`, `frame` and the input crop added.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut meta = self.metadata.clone();
        meta.insert("format".into(), FORMAT.into());
        meta.insert("frame".into(), format!("{FRAME_W}x{FRAME_H}"));
        meta.insert(
            "input".into(),
            format!("rows {INPUT_TOP}..{} of the frame, grey/255, mean of {INPUT_SCALE}x{INPUT_SCALE} blocks: 1x{IN_H}x{IN_W}", INPUT_TOP + INPUT_ROWS),
        );
        let mut header = serde_json::Map::new();
        header.insert("__metadata__".into(), serde_json::to_value(&meta).unwrap_or_default());
        let mut data = Vec::new();
        for (name, shape) in ARCH.tensors() {
            let v = self.tensors.get(&name).map(Vec::as_slice).unwrap_or(&[]);
            let a = data.len();
            data.extend(v.iter().flat_map(|x| x.to_le_bytes()));
            header.insert(
                name,
                serde_json::json!({"dtype": "F32", "shape": shape, "data_offsets": [a, data.len()]}),
            );
        }
        let mut h = serde_json::Value::Object(header).to_string().into_bytes();
        // safetensors pads the header with spaces to a multiple of 8 bytes.
        while !h.len().is_multiple_of(8) {
            h.push(b' ');
        }
        let mut out = (h.len() as u64).to_le_bytes().to_vec();
        out.extend(h);
        out.extend(data);
        out
    }

    /// Writes the file (through a temporary beside it, so a reader never sees half of one).
    pub fn save(&self, path: &Path) -> Result<(), PilotError> {
        let io = |error| PilotError::Io {
            path: path.to_path_buf(),
            error,
        };
        let tmp = path.with_extension("safetensors.tmp");
        std::fs::write(&tmp, self.to_bytes()).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }
}

/// Step 1: the network's input from a frame of [`FRAME_W`]×[`FRAME_H`] pixels, into `out`
/// (`IN_H × IN_W` values, row-major). A frame of another size gives `false`.
pub fn input_from_frame(frame: &RgbImage, out: &mut [f32]) -> bool {
    if frame.width() != FRAME_W || frame.height() != FRAME_H || out.len() != IN_H * IN_W {
        return false;
    }
    let s = INPUT_SCALE as usize;
    let w = FRAME_W as usize;
    let raw = frame.as_raw();
    let norm = 1.0 / (255.0 * (s * s) as f32);
    // Channel sums per block in integers (exact), weighted once per block.
    let mut sums = [[0u32; 3]; IN_W];
    for (oy, row_out) in out.chunks_exact_mut(IN_W).enumerate() {
        sums.iter_mut().for_each(|c| *c = [0; 3]);
        for dy in 0..s {
            let y = INPUT_TOP as usize + oy * s + dy;
            let row = &raw[y * w * 3..(y + 1) * w * 3];
            for (acc, block) in sums.iter_mut().zip(row.chunks_exact(3 * s)) {
                for px in block.chunks_exact(3) {
                    acc[0] += px[0] as u32;
                    acc[1] += px[1] as u32;
                    acc[2] += px[2] as u32;
                }
            }
        }
        for (o, c) in row_out.iter_mut().zip(&sums) {
            *o = (0.299 * c[0] as f32 + 0.587 * c[1] as f32 + 0.114 * c[2] as f32) * norm;
        }
    }
    true
}

/// The network with its weights re-ordered for the car's kernels (channels last).
#[derive(Debug, Clone)]
pub struct PilotNet {
    /// Per convolution: weights `[ky][kx][cin][cout]`, bias `[cout]`.
    convs: Vec<(Vec<f32>, Vec<f32>)>,
    /// `fc1` weights `[flat index in HWC order][hidden]`, bias.
    fc1: (Vec<f32>, Vec<f32>),
    /// `fc2` weights `[hidden]`, bias.
    fc2: (Vec<f32>, f32),
}

/// Scratch activations for [`PilotNet::forward`] (allocated once).
#[derive(Debug, Clone)]
pub struct Scratch {
    acts: [Vec<f32>; 3],
    hidden: Vec<f32>,
}

impl Default for Scratch {
    fn default() -> Self {
        let s = ARCH.sizes();
        Self {
            acts: std::array::from_fn(|i| vec![0.0; s[i + 1].0 * s[i + 1].1 * ARCH.convs[i].cout]),
            hidden: vec![0.0; ARCH.hidden],
        }
    }
}

impl PilotNet {
    /// The network of `w` (shapes were checked when `w` was read); [`NEGLIGIBLE`] weights
    /// become zeros.
    pub fn new(w: &PilotWeights) -> Self {
        let t = |n: &str| -> Vec<f32> { w.tensors.get(n).map(|v| v.iter().copied().map(flush).collect()).unwrap_or_default() };
        let convs = ARCH
            .convs
            .iter()
            .map(|c| {
                let src = t(&format!("{}.weight", c.name));
                let mut dst = vec![0.0; src.len()];
                for co in 0..c.cout {
                    for ci in 0..c.cin {
                        for ky in 0..c.k {
                            for kx in 0..c.k {
                                dst[((ky * c.k + kx) * c.cin + ci) * c.cout + co] =
                                    src[((co * c.cin + ci) * c.k + ky) * c.k + kx];
                            }
                        }
                    }
                }
                (dst, t(&format!("{}.bias", c.name)))
            })
            .collect();
        // fc1's input index is CHW (ONNX Flatten); the kernels flatten HWC.
        let (h, wd) = ARCH.sizes()[3];
        let c = ARCH.convs[2].cout;
        let src = t("fc1.weight");
        let mut fc1 = vec![0.0; src.len()];
        for j in 0..ARCH.hidden {
            for ch in 0..c {
                for y in 0..h {
                    for x in 0..wd {
                        fc1[((y * wd + x) * c + ch) * ARCH.hidden + j] = src[j * ARCH.flat() + (ch * h + y) * wd + x];
                    }
                }
            }
        }
        Self {
            convs,
            fc1: (fc1, t("fc1.bias")),
            fc2: (t("fc2.weight"), t("fc2.bias").first().copied().unwrap_or(0.0)),
        }
    }

    /// Reads the weights file at `path` and builds the network.
    pub fn load(path: &Path) -> Result<Self, PilotError> {
        PilotWeights::load(path).map(|w| Self::new(&w))
    }

    /// Steps 2–3: the network's output for `input` (`IN_H × IN_W` values of
    /// [`input_from_frame`]).
    pub fn forward(&self, input: &[f32], s: &mut Scratch) -> f32 {
        let sz = ARCH.sizes();
        let [a1, a2, a3] = &mut s.acts;
        let (c1, c2, c3) = (&ARCH.convs[0], &ARCH.convs[1], &ARCH.convs[2]);
        conv_relu::<8>(input, sz[0], c1, &self.convs[0], a1);
        conv_relu::<16>(a1, sz[1], c2, &self.convs[1], a2);
        conv_relu::<24>(a2, sz[2], c3, &self.convs[2], a3);
        // fc1: one input value meets a contiguous row of the hidden units.
        let hid = &mut s.hidden;
        hid.copy_from_slice(&self.fc1.1);
        for (x, wrow) in a3.iter().zip(self.fc1.0.chunks_exact(ARCH.hidden)) {
            for (h, w) in hid.iter_mut().zip(wrow) {
                *h += x * w;
            }
        }
        hid.iter().zip(&self.fc2.0).fold(self.fc2.1, |acc, (h, w)| acc + h.max(0.0) * w)
    }
}

/// One convolution + ReLU, channels last: `x` is `(h, w, cin)`, `y` is `(ho, wo, COUT)`.
/// For a kernel row the `k·cin` input values are contiguous, and each meets a contiguous
/// `COUT` row of weights: the inner loop is a fixed-length multiply-add the compiler
/// vectorises.
fn conv_relu<const COUT: usize>(x: &[f32], (h, w): (usize, usize), c: &ConvSpec, (wt, b): &(Vec<f32>, Vec<f32>), y: &mut [f32]) {
    debug_assert_eq!(c.cout, COUT);
    let (k, s, cin) = (c.k, c.stride, c.cin);
    let (ho, wo) = ((h - k) / s + 1, (w - k) / s + 1);
    let bias: [f32; COUT] = std::array::from_fn(|i| b[i]);
    let row_len = k * cin;
    for oy in 0..ho {
        for ox in 0..wo {
            let mut acc = bias;
            for ky in 0..k {
                let start = ((oy * s + ky) * w + ox * s) * cin;
                let xs = &x[start..start + row_len];
                let ws = &wt[ky * row_len * COUT..(ky + 1) * row_len * COUT];
                for (xv, wrow) in xs.iter().zip(ws.chunks_exact(COUT)) {
                    for (a, wv) in acc.iter_mut().zip(wrow) {
                        *a += xv * wv;
                    }
                }
            }
            let out = &mut y[(oy * wo + ox) * COUT..(oy * wo + ox + 1) * COUT];
            for (o, a) in out.iter_mut().zip(acc) {
                *o = a.max(0.0);
            }
        }
    }
}

/// Settings of the learned pilot (`[steering]` converts into them).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnedOptions {
    /// Output clamp, steer units 0..=1.
    pub max_steer: f64,
    /// Largest |Δsteer| per second.
    pub slew_rate: f64,
}

/// Steering by the learned network.
#[derive(Debug, Clone)]
pub struct Learned {
    net: Arc<PilotNet>,
    opts: LearnedOptions,
    input: Vec<f32>,
    scratch: Scratch,
    output: f64,
    raw: Option<f64>,
}

impl Learned {
    /// The pilot `net` with `opts`.
    pub fn new(net: Arc<PilotNet>, opts: LearnedOptions) -> Self {
        Self {
            net,
            opts,
            input: vec![0.0; IN_H * IN_W],
            scratch: Scratch::default(),
            output: 0.0,
            raw: None,
        }
    }

    /// The network's own output on the last frame, before the clamp and the rate limit
    /// (`None` before the first frame, or on a frame of the wrong size).
    pub fn raw(&self) -> Option<f64> {
        self.raw
    }
}

impl Steering for Learned {
    fn method(&self) -> SteeringMethod {
        SteeringMethod::Learned
    }

    fn steer(&mut self, input: &SteeringInput<'_>, dt: f64) -> f64 {
        if !input_from_frame(input.frame, &mut self.input) {
            self.raw = None;
            return self.output; // a frame of another size: hold the wheel
        }
        let raw = self.net.forward(&self.input, &mut self.scratch) as f64;
        self.raw = Some(raw);
        if !(dt.is_finite() && dt > 0.0) {
            return self.output;
        }
        self.output = limit(raw, self.output, self.opts.max_steer, self.opts.slew_rate, dt);
        self.output
    }

    fn reset(&mut self) {
        self.raw = None;
    }

    fn clone_box(&self) -> Box<dyn Steering> {
        Box::new(self.clone())
    }
}

impl Params for Learned {
    const PARAMS: &'static [Param<Learned>] = &[
        Param {
            info: MAX_STEER,
            get: |p| p.opts.max_steer,
            set: |p, v| p.opts.max_steer = v,
        },
        Param {
            info: SLEW_RATE,
            get: |p| p.opts.slew_rate,
            set: |p, v| p.opts.slew_rate = v,
        },
    ];
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Weights with a seeded pattern (not trained): enough for shapes and layouts.
    pub(crate) fn pattern_weights() -> PilotWeights {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.4
        };
        PilotWeights {
            tensors: ARCH
                .tensors()
                .into_iter()
                .map(|(n, s)| (n, (0..s.iter().product::<usize>()).map(|_| next()).collect()))
                .collect(),
            metadata: BTreeMap::new(),
        }
    }

    #[test]
    fn the_shapes_are_the_documented_ones() {
        assert_eq!(ARCH.sizes(), [(18, 80), (7, 38), (3, 18), (1, 16)]);
        assert_eq!(ARCH.flat(), 384);
        assert_eq!(ARCH.macs(), 53_200 + 62_208 + 55_296 + 12_288 + 32);
        let params: usize = ARCH.tensors().iter().map(|(_, s)| s.iter().product::<usize>()).sum();
        assert_eq!(params, 17_209);
    }

    #[test]
    fn file_round_trips_and_bad_files_name_what_is_wrong() {
        let w = pattern_weights();
        let bytes = w.to_bytes();
        let back = PilotWeights::from_bytes(&bytes).unwrap();
        assert_eq!(back.tensors, w.tensors);
        assert_eq!(back.metadata["format"], FORMAT);
        // a tensor of another shape (the header edited: the writer always writes ARCH's)
        let hdr_len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
        let hdr = String::from_utf8(bytes[8..8 + hdr_len].to_vec()).unwrap();
        let bad = hdr.replacen("\"shape\":[32,384]", "\"shape\":[16,768]", 1);
        assert_ne!(bad, hdr);
        let mut b2 = (bad.len() as u64).to_le_bytes().to_vec();
        b2.extend(bad.as_bytes());
        b2.extend(&bytes[8 + hdr_len..]);
        let e = PilotWeights::from_bytes(&b2).unwrap_err();
        assert!(e.contains("`fc1.weight` has shape [16, 768], this network's is [32, 384]"), "{e}");
        // truncated, not safetensors at all, wrong format
        let e = PilotWeights::from_bytes(&bytes[..bytes.len() - 4]).unwrap_err();
        assert!(e.contains("fc2.bias") && e.contains("data_offsets"), "{e}");
        let e = PilotWeights::from_bytes(b"hello").unwrap_err();
        assert!(e.contains("not a safetensors file"), "{e}");
        let mut other = bytes.clone();
        let at = other.windows(FORMAT.len()).position(|w| w == FORMAT.as_bytes()).unwrap();
        other[at + FORMAT.len() - 1] = b'9';
        let e = PilotWeights::from_bytes(&other).unwrap_err();
        assert!(e.contains("format \"rccar-pilot-9\"; this rccar reads \"rccar-pilot-1\""), "{e}");
    }

    /// The channels-last kernels against a direct reading of the definition (PyTorch layouts,
    /// CHW), on seeded weights and input: equal to 1e-5.
    #[test]
    fn forward_matches_the_definition() {
        let w = pattern_weights();
        let net = PilotNet::new(&w);
        let input: Vec<f32> = (0..IN_H * IN_W).map(|i| ((i * 37) % 101) as f32 / 100.0).collect();
        let got = net.forward(&input, &mut Scratch::default());
        // the definition
        let mut x = input.clone();
        let mut hw = (IN_H, IN_W);
        for c in &ARCH.convs {
            let wt = &w.tensors[&format!("{}.weight", c.name)];
            let b = &w.tensors[&format!("{}.bias", c.name)];
            let (ho, wo) = ((hw.0 - c.k) / c.stride + 1, (hw.1 - c.k) / c.stride + 1);
            let mut y = vec![0.0f32; c.cout * ho * wo];
            for co in 0..c.cout {
                for oy in 0..ho {
                    for ox in 0..wo {
                        let mut a = b[co];
                        for ci in 0..c.cin {
                            for ky in 0..c.k {
                                for kx in 0..c.k {
                                    a += wt[((co * c.cin + ci) * c.k + ky) * c.k + kx]
                                        * x[(ci * hw.0 + oy * c.stride + ky) * hw.1 + ox * c.stride + kx];
                                }
                            }
                        }
                        y[(co * ho + oy) * wo + ox] = a.max(0.0);
                    }
                }
            }
            x = y;
            hw = (ho, wo);
        }
        let (f1, b1) = (&w.tensors["fc1.weight"], &w.tensors["fc1.bias"]);
        let h: Vec<f32> = (0..ARCH.hidden)
            .map(|j| (b1[j] + (0..x.len()).map(|i| f1[j * x.len() + i] * x[i]).sum::<f32>()).max(0.0))
            .collect();
        let want = w.tensors["fc2.bias"][0] + h.iter().zip(&w.tensors["fc2.weight"]).map(|(a, b)| a * b).sum::<f32>();
        assert!(want.abs() > 0.01, "a degenerate test: {want}");
        assert!((got - want).abs() <= 1e-5 * want.abs().max(1.0), "{got} vs {want}");
    }

    #[test]
    fn input_is_the_block_mean_of_grey_over_the_crop() {
        let mut f = RgbImage::new(FRAME_W, FRAME_H);
        f.put_pixel(4, INPUT_TOP + 4, image::Rgb([255, 255, 255]));
        f.put_pixel(0, INPUT_TOP - 1, image::Rgb([255, 255, 255])); // above the crop
        let mut out = vec![0.0; IN_H * IN_W];
        assert!(input_from_frame(&f, &mut out));
        assert!((out[IN_W + 1] - 1.0 / 16.0).abs() < 1e-6, "{}", out[IN_W + 1]);
        assert_eq!(out.iter().filter(|v| **v != 0.0).count(), 1);
        assert!(!input_from_frame(&RgbImage::new(160, 120), &mut out));
    }
}
