//! The learned pilot's inference per frame (issue 29, must-show 3): the car's forward kernels
//! (src/control/learned.rs) side by side, in the same run, with onnxruntime (PyPI) running the
//! same network exported to ONNX, both on one thread.
//!
//! `cargo bench --bench pilot [-- --reps N]`
//!
//! 1. Weights: config/pilot.safetensors (the shipped pilot).
//! 2. Inputs: 32 simulator frames of the default track, turned into the network's input
//!    (`input_from_frame`), written as raw f32 for the Python side.
//! 3. onnxruntime (`$RCCAR_PYTHON`, else `python3`, with numpy, onnx and onnxruntime;
//!    tests/parity/requirements.txt): the weights file read with numpy, the graph built with
//!    `onnx.helper` (Conv → Relu ×3, Flatten, Gemm → Relu → Gemm), one session with
//!    `intra_op_num_threads = inter_op_num_threads = 1` and every graph optimisation, the inputs
//!    `[1,1,18,80]` one frame per `run`. It first checks that its outputs equal ours (≤ 1e-4).
//! 4. Alternating rounds of both sides (same machine load); each reports milliseconds per
//!    frame (wall) and its thread's CPU time per frame. Prints medians, minima and the ratio
//!    ours / onnxruntime; also our preprocessing (frame → input) apart.

#[path = "support/opencv.rs"]
mod opencv;
#[path = "support/cpu.rs"]
mod cpu;

use rccar::config::Config;
use rccar::control::learned::{input_from_frame, PilotNet, PilotWeights, Scratch, ARCH, IN_H, IN_W};
use rccar::sim::run::Simulation;
use rccar::sim::track::Track;
use std::path::Path;
use std::time::Instant;

const PY: &str = r#"
import json, struct, sys, time
import numpy as np
import onnx
from onnx import helper, TensorProto, numpy_helper
import onnxruntime as ort
a = json.loads(sys.argv[1])
raw = open(a["weights"], "rb").read()
n = struct.unpack("<Q", raw[:8])[0]
hdr = json.loads(raw[8:8 + n])
data = raw[8 + n:]
def t(name):
    h = hdr[name]
    s, e = h["data_offsets"]
    return np.frombuffer(data[s:e], dtype="<f4").reshape(h["shape"]).copy()
inits, nodes, x = [], [], "input"
for i, c in enumerate(a["convs"]):
    w, b = c["name"] + ".weight", c["name"] + ".bias"
    inits += [numpy_helper.from_array(t(w), w), numpy_helper.from_array(t(b), b)]
    nodes.append(helper.make_node("Conv", [x, w, b], ["c%d" % i], kernel_shape=[c["k"], c["k"]],
                                  strides=[c["stride"], c["stride"]], pads=[0, 0, 0, 0]))
    nodes.append(helper.make_node("Relu", ["c%d" % i], ["r%d" % i]))
    x = "r%d" % i
for name in ["fc1.weight", "fc1.bias", "fc2.weight", "fc2.bias"]:
    inits.append(numpy_helper.from_array(t(name), name))
nodes += [helper.make_node("Flatten", [x], ["flat"], axis=1),
          helper.make_node("Gemm", ["flat", "fc1.weight", "fc1.bias"], ["h"], transB=1),
          helper.make_node("Relu", ["h"], ["hr"]),
          helper.make_node("Gemm", ["hr", "fc2.weight", "fc2.bias"], ["steer"], transB=1)]
H, W = a["in_h"], a["in_w"]
g = helper.make_graph(nodes, "rccar_pilot", [helper.make_tensor_value_info("input", TensorProto.FLOAT, [1, 1, H, W])],
                      [helper.make_tensor_value_info("steer", TensorProto.FLOAT, [1, 1])], inits)
m = helper.make_model(g, opset_imports=[helper.make_opsetid("", 17)])
onnx.checker.check_model(m)
if a.get("save"):
    onnx.save(m, a["save"])
so = ort.SessionOptions()
so.intra_op_num_threads = 1
so.inter_op_num_threads = 1
so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
sess = ort.InferenceSession(m.SerializeToString(), so, providers=["CPUExecutionProvider"])
xs = np.fromfile(a["inputs"], dtype="<f4").reshape(-1, 1, 1, H, W)
outs = [float(sess.run(None, {"input": x})[0][0, 0]) for x in xs]
print(json.dumps({"ort": ort.__version__, "onnx": onnx.__version__, "outputs": outs}), flush=True)
for line in sys.stdin:
    reps = int(line)
    c0 = time.thread_time(); t0 = time.perf_counter()
    for _ in range(reps):
        for x in xs:
            sess.run(None, {"input": x})
    t1 = time.perf_counter(); c1 = time.thread_time()
    k = reps * len(xs)
    print(json.dumps([(t1 - t0) * 1e3 / k, (c1 - c0) * 1e3 / k]), flush=True)
"#;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps: usize = args
        .iter()
        .position(|a| a == "--reps")
        .and_then(|i| args.get(i + 1))
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // 1. weights
    let wpath = root.join("config/pilot.safetensors");
    let weights = PilotWeights::load(&wpath).unwrap_or_else(|e| panic!("{e}"));
    let net = PilotNet::new(&weights);
    // 2. inputs from simulator frames
    let track = Track::load(&root.join("config/tracks/default.toml")).expect("default track");
    let mut sim = Simulation::new(&Config::default(), &track).expect("simulation");
    let mut frames = Vec::new();
    let mut inputs: Vec<Vec<f32>> = Vec::new();
    for i in 0..32 * 40 {
        sim.step();
        if i % 40 == 39 {
            let mut x = vec![0.0f32; IN_H * IN_W];
            assert!(input_from_frame(sim.image(), &mut x));
            frames.push(sim.image().clone());
            inputs.push(x);
        }
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let raw = dir.path().join("inputs.f32");
    let bytes: Vec<u8> = inputs.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&raw, bytes).expect("inputs file");
    // 3. onnxruntime, and the check that both compute the same
    let convs: Vec<_> = ARCH
        .convs
        .iter()
        .map(|c| serde_json::json!({"name": c.name, "k": c.k, "stride": c.stride}))
        .collect();
    let save = std::env::var("RCCAR_PILOT_ONNX").unwrap_or_default();
    let req = serde_json::json!({"weights": wpath, "inputs": raw, "convs": convs, "in_h": IN_H, "in_w": IN_W, "save": save});
    let (mut py, first) = opencv::OpenCv::start(&opencv::python(), PY, &[req.to_string()]);
    let first: serde_json::Value = serde_json::from_str(&first).expect("helper's first line");
    let mut s = Scratch::default();
    let ours: Vec<f32> = inputs.iter().map(|x| net.forward(x, &mut s)).collect();
    let theirs: Vec<f64> = serde_json::from_value(first["outputs"].clone()).expect("outputs");
    let diff = ours
        .iter()
        .zip(&theirs)
        .map(|(a, b)| (*a as f64 - b).abs())
        .fold(0.0f64, f64::max);
    println!(
        "pilot network: {} multiply-adds, input 1x{IN_H}x{IN_W}; onnxruntime {} (onnx {}); max |ours - onnxruntime| over {} frames = {diff:.2e}",
        ARCH.macs(),
        first["ort"].as_str().unwrap_or("?"),
        first["onnx"].as_str().unwrap_or("?"),
        inputs.len()
    );
    assert!(diff <= 1e-4, "the ONNX export computes something else: {diff}");
    // 4. alternating rounds
    let rounds = 7;
    let per = (reps / rounds).max(1);
    let (mut ow, mut oc, mut rw, mut rc) = (vec![], vec![], vec![], vec![]);
    let mut sink = 0.0f32;
    for _ in 0..rounds {
        let c0 = cpu::thread_cpu_ns();
        let t0 = Instant::now();
        for _ in 0..per {
            for x in &inputs {
                sink += net.forward(std::hint::black_box(x), &mut s);
            }
        }
        let k = (per * inputs.len()) as f64;
        ow.push(t0.elapsed().as_secs_f64() * 1e3 / k);
        if let (Some(a), Some(b)) = (c0, cpu::thread_cpu_ns()) {
            oc.push((b - a) as f64 / 1e6 / k);
        }
        let t = py.times(&per.to_string());
        rw.push(t[0]);
        rc.push(t[1]);
    }
    std::hint::black_box(sink);
    // preprocessing apart (frame → input)
    let t0 = Instant::now();
    let mut x = vec![0.0f32; IN_H * IN_W];
    for _ in 0..per {
        for f in &frames {
            input_from_frame(std::hint::black_box(f), &mut x);
        }
    }
    let pre = t0.elapsed().as_secs_f64() * 1e3 / (per * frames.len()) as f64;
    let (mo, mr) = (median(ow.clone()), median(rw.clone()));
    println!(
        "ours (rccar kernels, 1 thread): median {:.4} ms/frame (min {:.4}), CPU {:.4} ms",
        mo,
        ow.iter().cloned().fold(f64::INFINITY, f64::min),
        if oc.is_empty() { f64::NAN } else { median(oc.clone()) }
    );
    println!(
        "onnxruntime (1 thread):         median {:.4} ms/frame (min {:.4}), CPU {:.4} ms",
        mr,
        rw.iter().cloned().fold(f64::INFINITY, f64::min),
        median(rc.clone())
    );
    println!(
        "ratio ours / onnxruntime: {:.2} (wall), {:.2} (CPU); preprocessing (frame -> input) {:.4} ms/frame",
        mo / mr,
        if oc.is_empty() { f64::NAN } else { median(oc) / median(rc) },
        pre
    );
}
