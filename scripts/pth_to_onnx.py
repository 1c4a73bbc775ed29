#!/usr/bin/env python3
"""Export a pytorch-CycleGAN-and-pix2pix generator checkpoint
(``latest_net_G_A.pth`` of a ``resnet_Nblocks`` model with instance norm)
to ONNX for ``murk camera`` / ``murk rain --generator``, without torch.

    pip install numpy onnx            # onnxruntime too for --check
    python3 scripts/pth_to_onnx.py checkpoints/fog_heavy/latest_net_G_A.pth fog_heavy.onnx --check

The .pth is read with a restricted unpickler (only the globals a state_dict
uses: OrderedDict, torch._utils._rebuild_tensor_v2 and the storage types;
anything else is refused, so a checkpoint cannot run code). The graph has a
dynamic H and W (multiples of 4; murk pads images to that), input in
[-1, 1] and a tanh output. ``--check`` runs the exported model in
onnxruntime on a random 64x64 input and compares it with the numpy forward
pass of ``cyclegan_onnx.py``.
"""

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import cyclegan_onnx as cg  # noqa: E402


def export(pth, onnx_path):
    """Reads ``pth`` and writes the ONNX model to ``onnx_path`` atomically;
    returns the state_dict and (ngf, n_blocks)."""
    sd = cg.read_state_dict(pth)
    model = cg.build_onnx(sd, name=os.path.splitext(os.path.basename(pth))[0])
    tmp = onnx_path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(model.SerializeToString())
    os.replace(tmp, onnx_path)
    ngf, n, *_ = cg.layout(sd)
    return sd, (ngf, n)


def check(sd, onnx_path, size=64, seed=0):
    """Max |onnxruntime - numpy| on a random size x size input."""
    import onnxruntime as ort

    x = np.random.default_rng(seed).uniform(-1, 1, (1, 3, size, size)).astype(np.float32)
    sess = ort.InferenceSession(onnx_path, providers=["CPUExecutionProvider"])
    got = sess.run(["output"], {"input": x})[0][0]
    want = cg.numpy_forward(sd, x[0])
    return float(np.abs(got - want).max())


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pth", help="latest_net_G_A.pth (torch zip format)")
    ap.add_argument("onnx", help="output .onnx")
    ap.add_argument("--check", action="store_true", help="compare onnxruntime with the numpy forward pass")
    a = ap.parse_args()
    try:
        sd, (ngf, n) = export(a.pth, a.onnx)
    except cg.CheckpointError as e:
        sys.exit(f"{a.pth}: {e}")
    print(f"{a.pth} -> {a.onnx}: resnet_{n}blocks, ngf {ngf}, {sum(v.size for v in sd.values())} parameters")
    if a.check:
        err = check(sd, a.onnx)
        print(f"check: max |onnxruntime - numpy| = {err:.2e} on a 64x64 input")
        if not err < 1e-4:
            sys.exit("check failed: the exported graph does not match the numpy forward pass")


if __name__ == "__main__":
    main()
