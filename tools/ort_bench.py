#!/usr/bin/env python3
"""ONNX Runtime's half of `cargo xtask ort-bench` (issue 13).

Reads what `train-host/eval/examples/ort_bench.rs` wrote into DIR/<model>/, rebuilds
each network as an ONNX graph (frame, centring, per-point MatMul + Add + Relu,
ReduceMax over the points, Concat with the template feature, the head), checks
that ONNX Runtime's f32 outputs match ours, quantizes it statically with
ONNX Runtime's own tool (QDQ, per-channel int8 weights, uint8 activations,
calibrated on the benchmark clouds), times both sessions on one thread the
in turn with ours round by round (`bench_timing.paired`, our rounds run by
OURS, `ort_bench serve`), and prints the ratios: of the median rounds, and
of the best rounds (on a shared machine the median moves with whatever else
runs; the best round is the closest each side gets to its own cost).

Usage: ort_bench.py DIR OURS
"""

import json
import pathlib
import sys

import numpy as np
import onnx
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper
from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

from bench_timing import ROUNDS, Ours, paired, time_round

POINTS = 1024
OPSET = 17


def build(net, weights):
    """The network of network.json / weights.f32 as an ONNX model."""
    layers, offset = [], 0
    for shape in net["layers"]:
        n_w, n_b = shape["inputs"] * shape["outputs"], shape["outputs"]
        w = weights[offset : offset + n_w].reshape(shape["outputs"], shape["inputs"])
        b = weights[offset + n_w : offset + n_w + n_b]
        layers.append((w, b, shape["relu"]))
        offset += n_w + n_b
    template = weights[offset : offset + net["feature"]].reshape(1, -1)
    if offset + net["feature"] != len(weights):
        raise SystemExit("weights.f32 does not match network.json")

    inits, nodes = [], []

    def const(name, value):
        inits.append(numpy_helper.from_array(np.asarray(value, dtype=np.float32), name))
        return name

    nodes.append(helper.make_node("Sub", ["points", const("centre", net["frame_centre"])], ["p0"]))
    nodes.append(helper.make_node("Mul", ["p0", const("scale", [net["frame_scale"]])], ["p1"]))
    x = "p1"
    if net["centre_source"]:
        nodes.append(helper.make_node("ReduceMean", [x], ["mean"], axes=[0], keepdims=1))
        nodes.append(helper.make_node("Sub", [x, "mean"], ["p2"]))
        x = "p2"
    for i, (w, b, relu) in enumerate(layers):
        if i == net["encoder_layers"]:
            nodes.append(helper.make_node("ReduceMax", [x], ["feature"], axes=[0], keepdims=1))
            nodes.append(
                helper.make_node("Concat", [const("template", template), "feature"], ["h0"], axis=1)
            )
            x = "h0"
        nodes.append(helper.make_node("MatMul", [x, const(f"w{i}", w.T.copy())], [f"m{i}"]))
        y = f"y{i}" if relu else "pose"
        nodes.append(helper.make_node("Add", [f"m{i}", const(f"b{i}", b)], [f"a{i}" if relu else y]))
        if relu:
            nodes.append(helper.make_node("Relu", [f"a{i}"], [y]))
        x = y
    graph = helper.make_graph(
        nodes,
        "pcrnet",
        [helper.make_tensor_value_info("points", TensorProto.FLOAT, ["n", 3])],
        [helper.make_tensor_value_info("pose", TensorProto.FLOAT, [1, 7])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)])
    onnx.checker.check_model(model)
    return model


class Clouds(CalibrationDataReader):
    def __init__(self, clouds):
        self.it = iter([{"points": c} for c in clouds])

    def get_next(self):
        return next(self.it, None)


def session(path):
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    return ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])


def main():
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    root = pathlib.Path(sys.argv[1])
    ours_side = Ours(sys.argv[2], root)
    rows = []
    for name in ["embedded", "paper"]:
        d = root / name
        net = json.loads((d / "network.json").read_text())
        ours = json.loads((d / "ours.json").read_text())
        weights = np.fromfile(d / "weights.f32", dtype="<f4")
        clouds = np.fromfile(d / "clouds.f32", dtype="<f4").reshape(-1, POINTS, 3)
        clouds = [np.ascontiguousarray(c) for c in clouds]
        f32_path, int8_path = d / "model-f32.onnx", d / "model-int8.onnx"
        onnx.save(build(net, weights), f32_path)
        quantize_static(
            str(f32_path),
            str(int8_path),
            Clouds(clouds[:16]),
            quant_format=QuantFormat.QDQ,
            per_channel=True,
            activation_type=QuantType.QUInt8,
            weight_type=QuantType.QInt8,
        )
        f32_sess, int8_sess = session(f32_path), session(int8_path)
        theirs = np.array([f32_sess.run(None, {"points": c})[0][0] for c in clouds])
        mine = np.array(ours["outputs"], dtype=np.float32)
        rel = float(np.max(np.abs(theirs - mine)) / max(float(np.max(np.abs(mine))), 1e-30))
        if rel > 1e-4:
            raise SystemExit(f"{name}: ONNX Runtime's f32 outputs differ from ours by {rel:.2e} (relative)")
        times = {}
        for precision, sess in [("f32", f32_sess), ("int8", int8_sess)]:
            times[precision] = paired(
                lambda: ours_side.round(f"{name} {precision}"),
                lambda: time_round(lambda c: sess.run(None, {"points": c}), clouds),
            )
        (ours_f32, ours_f32_best), (ort_f32, ort_f32_best) = times["f32"]
        (ours_int8, ours_int8_best), (ort_int8, ort_int8_best) = times["int8"]
        widths = "-".join(map(str, ours["encoder"])) + " / " + "-".join(map(str, ours["head"]))
        rows.append(
            {
                "model": name,
                "widths": widths,
                "ours_f32_ms": ours_f32,
                "ort_f32_ms": ort_f32,
                "ours_int8_ms": ours_int8,
                "ort_int8_ms": ort_int8,
                "ours_f32_best_ms": ours_f32_best,
                "ort_f32_best_ms": ort_f32_best,
                "ours_int8_best_ms": ours_int8_best,
                "ort_int8_best_ms": ort_int8_best,
                "f32_max_rel_diff": rel,
            }
        )
    ours_side.close()
    (root / "results.json").write_text(json.dumps(rows, indent=1))
    print(
        f"onnxruntime {ort.__version__}, one thread, {ROUNDS} rounds each side in turn; "
        f"clouds: {(root / 'clouds.txt').read_text()}"
    )
    for rule, key in [("median round", ""), ("best round", "_best")]:
        print()
        print(f"| model ({rule}) | ours f32 ms | ORT f32 ms | ours / ORT | ours int8 ms | ORT int8 ms | ours / ORT | f32 outputs agree to |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            of, tf = r[f"ours_f32{key}_ms"], r[f"ort_f32{key}_ms"]
            oi, ti = r[f"ours_int8{key}_ms"], r[f"ort_int8{key}_ms"]
            print(
                f"| {r['model']} {r['widths']} | {of:.3f} | {tf:.3f} | {of / tf:.2f}x | "
                f"{oi:.3f} | {ti:.3f} | {oi / ti:.2f}x | {r['f32_max_rel_diff']:.1e} |"
            )

if __name__ == "__main__":
    main()
