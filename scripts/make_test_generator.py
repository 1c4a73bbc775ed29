#!/usr/bin/env python3
"""Make murk's tiny test generator and its independent references
(``infer/tests/data/gan/``), or a full-size random generator for the bench.

    pip install numpy onnx onnxruntime
    python3 scripts/make_test_generator.py                     # the committed test data
    python3 scripts/make_test_generator.py --full /tmp/resnet9_ngf64.onnx   # bench model (~45 MB)

The tiny generator is pytorch-CycleGAN-and-pix2pix's resnet generator with
ngf 4 and 2 residual blocks: the same op set as resnet_9blocks (reflect pad,
conv, instance norm, relu, residual add, conv-transpose, tanh). It is made
the way a user's model is: random weights -> a ``.pth`` in torch's zip
format (written without torch) -> ``scripts/pth_to_onnx.py``'s exporter ->
ONNX. The references come from the numpy forward pass in
``cyclegan_onnx.py`` (float64, written from the layer definitions), and are
checked here against Python onnxruntime running the exported graph.

Files written (all small):

- ``tiny_net_G_A.pth``: the checkpoint (torch.save layout);
- ``tiny_generator.onnx``: the exported model;
- ``input_odd.png`` (50x38, not a multiple of 4) and ``input_even.png``
  (32x24);
- ``padded_output_odd.f32``: the network's float output (NCHW, little-endian
  f32, 3x40x52) on ``input_odd.png`` scaled by x/127.5-1 and reflect-padded
  at the bottom and right to 40x52 (what murk does);
- ``output_odd.png`` / ``output_even.png``: the 8-bit images murk must
  produce: float output cropped to the input's size, (y+1)/2*255 rounded
  and clamped;
- ``reference.json``: sizes, tolerances and the self-check figures;
- ``bad_gray.onnx`` (1 channel) and ``bad_shrinks.onnx`` (halves the size):
  models murk must refuse.

Self-checks (the script exits non-zero when one fails): the .pth round
trip is exact; a pickle naming another global is refused; onnxruntime
agrees with numpy to 1e-4; and a perturbed weight (+0.05 on one residual
conv) moves the output by far more than that tolerance, so a comparison at
the stated tolerance can fail.
"""

import argparse
import io
import json
import os
import pickle
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cyclegan_onnx as cg  # noqa: E402
import pth_to_onnx  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "..", "infer", "tests", "data", "gan")
TOL_FLOAT = 1e-4  # |murk - numpy| on the tanh output


def write_png(path, rgb):
    """Minimal RGB8 PNG writer (zlib + crc), so no imaging package is needed."""
    import struct
    import zlib

    h, w, _ = rgb.shape
    raw = b"".join(b"\x00" + rgb[y].astype(np.uint8).tobytes() for y in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) \
        + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def test_image(w, h, seed):
    """A street-like test picture: gradients, a bright block, noise."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.stack([
        40 + 180 * xx / max(w - 1, 1),
        60 + 150 * yy / max(h - 1, 1),
        120 + 60 * np.sin(xx / 3.0) * np.cos(yy / 4.0),
    ], axis=-1)
    img[h // 4: h // 2, w // 3: w // 2] = [250, 240, 30]
    img += rng.normal(0, 12, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def preprocess(img):
    """uint8 HxWx3 -> float32 3xHxW in [-1, 1], as murk computes it (f32)."""
    x = img.astype(np.float32) / np.float32(127.5) - np.float32(1.0)
    return np.ascontiguousarray(x.transpose(2, 0, 1))


def pad_to4(x):
    """Reflect-pad 3xHxW at the bottom and right to multiples of 4."""
    _, h, w = x.shape
    return np.pad(x, ((0, 0), (0, (-h) % 4), (0, (-w) % 4)), mode="reflect")


def postprocess(y, h, w):
    """3xH'xW' tanh output -> uint8 HxWx3: crop, (y+1)/2*255, round, clamp."""
    v = (y[:, :h, :w].astype(np.float64) + 1.0) / 2.0 * 255.0
    return np.clip(np.round(v), 0, 255).astype(np.uint8).transpose(1, 2, 0)


def ort_run(onnx_path, x):
    import onnxruntime as ort

    sess = ort.InferenceSession(onnx_path, providers=["CPUExecutionProvider"])
    return sess.run(["output"], {"input": x[None].astype(np.float32)})[0][0]


def self_check_reader(sd, tmp):
    pth = os.path.join(tmp, "rt.pth")
    cg.write_state_dict(pth, sd)
    back = cg.read_state_dict(pth)
    assert list(back) == list(sd), "round trip changed the keys"
    for k in sd:
        assert back[k].dtype == np.float32 and np.array_equal(back[k], sd[k]), f"round trip changed {k}"

    class Evil:
        def __reduce__(self):
            return (os.system, ("echo pwned",))

    evil = os.path.join(tmp, "evil.pth")
    import zipfile
    with zipfile.ZipFile(evil, "w") as zf:
        zf.writestr("archive/data.pkl", pickle.dumps(Evil(), protocol=2))
    try:
        cg.read_state_dict(evil)
    except cg.CheckpointError as e:
        print(f"self-check: malicious pickle refused ({e})")
    else:
        sys.exit("self-check failed: a pickle naming os.system was loaded")


def make_tiny():
    os.makedirs(OUT, exist_ok=True)
    sd = cg.random_state_dict(ngf=4, n_blocks=2, seed=2024)
    with tempfile.TemporaryDirectory() as tmp:
        self_check_reader(sd, tmp)
    pth = os.path.join(OUT, "tiny_net_G_A.pth")
    onnx_path = os.path.join(OUT, "tiny_generator.onnx")
    cg.write_state_dict(pth, sd, archive="tiny_net_G_A")
    sd_read, (ngf, n) = pth_to_onnx.export(pth, onnx_path)

    meta = {"generator": "tiny_generator.onnx", "ngf": int(ngf), "n_blocks": int(n),
            "float_tolerance": TOL_FLOAT,
            "u8_tolerance": "each byte within 1; at most 1 % of bytes differ (rounding of values within 1e-4 of a .5 step)",
            "images": {}}
    for tag, (w, h, seed) in {"odd": (50, 38, 1), "even": (32, 24, 2)}.items():
        img = test_image(w, h, seed)
        write_png(os.path.join(OUT, f"input_{tag}.png"), img)
        x = pad_to4(preprocess(img))
        ref = cg.numpy_forward(sd_read, x)
        got = ort_run(onnx_path, x)
        err = float(np.abs(got - ref).max())
        print(f"{tag}: {w}x{h} padded to {x.shape[2]}x{x.shape[1]}: max |onnxruntime - numpy| = {err:.2e}, "
              f"output range [{ref.min():.3f}, {ref.max():.3f}], std {ref.std():.3f}")
        if not err < TOL_FLOAT:
            sys.exit(f"self-check failed: onnxruntime and numpy differ by {err}")
        out = postprocess(ref, h, w)
        write_png(os.path.join(OUT, f"output_{tag}.png"), out)
        entry = {"input": f"input_{tag}.png", "output": f"output_{tag}.png", "width": w, "height": h,
                 "padded_width": int(x.shape[2]), "padded_height": int(x.shape[1]),
                 "onnxruntime_vs_numpy_max_abs": err}
        if tag == "odd":
            ref.astype("<f4").tofile(os.path.join(OUT, "padded_output_odd.f32"))
            entry["padded_output"] = "padded_output_odd.f32"
            # The comparison can fail: perturb one residual conv weight.
            sd_bad = {k: v.copy() for k, v in sd_read.items()}
            sd_bad["model.10.conv_block.1.weight"][0, 0, 1, 1] += 0.05
            with tempfile.TemporaryDirectory() as tmp:
                bad = os.path.join(tmp, "bad.onnx")
                with open(bad, "wb") as f:
                    f.write(cg.build_onnx(sd_bad).SerializeToString())
                moved = float(np.abs(ort_run(bad, x) - ref).max())
            print(f"self-check: a +0.05 perturbation of one weight moves the output by {moved:.2e}")
            if not moved > 100 * TOL_FLOAT:
                sys.exit("self-check failed: a perturbed weight stays within the tolerance")
            entry["perturbed_weight_max_abs"] = moved
        meta["images"][tag] = entry
    write_bad_models()
    with open(os.path.join(OUT, "reference.json"), "w") as f:
        json.dump(meta, f, indent=2)
        f.write("\n")
    sizes = {n: os.path.getsize(os.path.join(OUT, n)) for n in sorted(os.listdir(OUT))}
    print("wrote", ", ".join(f"{n} ({s} B)" for n, s in sizes.items()))


def write_bad_models():
    """Two tiny models murk must refuse: a 1-channel one (refused at load)
    and one that halves the image (refused after the run)."""
    from onnx import TensorProto, helper

    def save(name, node, in_shape, out_shape):
        g = helper.make_graph([node], name,
                              [helper.make_tensor_value_info("input", TensorProto.FLOAT, in_shape)],
                              [helper.make_tensor_value_info("output", TensorProto.FLOAT, out_shape)])
        m = helper.make_model(g, opset_imports=[helper.make_opsetid("", cg.OPSET)], producer_name="murk tests")
        m.ir_version = 8
        with open(os.path.join(OUT, name + ".onnx"), "wb") as f:
            f.write(m.SerializeToString())

    save("bad_gray", helper.make_node("Relu", ["input"], ["output"]), [1, 1, "H", "W"], [1, 1, "H", "W"])
    save("bad_shrinks", helper.make_node("MaxPool", ["input"], ["output"], kernel_shape=[2, 2], strides=[2, 2]),
         [1, 3, "H", "W"], [1, 3, "h", "w"])


def make_full(path, check):
    sd = cg.random_state_dict(ngf=64, n_blocks=9, seed=64)
    with tempfile.TemporaryDirectory() as tmp:
        pth = os.path.join(tmp, "latest_net_G_A.pth")
        cg.write_state_dict(pth, sd)
        sd_read, (ngf, n) = pth_to_onnx.export(pth, path)
    print(f"wrote {path}: resnet_{n}blocks ngf {ngf} with random weights ({os.path.getsize(path)} B)")
    if check:
        err = pth_to_onnx.check(sd_read, path, size=64)
        print(f"check: max |onnxruntime - numpy| = {err:.2e} on a 64x64 input")
        if not err < TOL_FLOAT:
            sys.exit("check failed")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--full", metavar="PATH", help="write a resnet_9blocks ngf 64 random generator to PATH instead")
    ap.add_argument("--check", action="store_true", help="with --full: compare onnxruntime with numpy")
    a = ap.parse_args()
    if a.full:
        make_full(a.full, a.check)
    else:
        make_tiny()


if __name__ == "__main__":
    main()
