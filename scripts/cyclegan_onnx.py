"""CycleGAN ``resnet_*blocks`` generators without torch: read a ``.pth``
state_dict, write one (for tests), build the ONNX graph, and run an
independent numpy forward pass.

This module backs ``scripts/pth_to_onnx.py`` (the exporter murk documents)
and ``scripts/make_test_generator.py`` (the tiny test generator and its
references). It needs ``numpy`` and ``onnx`` only.

The generator is pytorch-CycleGAN-and-pix2pix's ``ResnetGenerator`` with
instance norm (no affine parameters, so ``use_bias`` is true on every conv),
reflect padding and no dropout, whose ``nn.Sequential`` indices give the
state_dict keys::

    model.0  ReflectionPad2d(3)        model.1  Conv2d(in, ngf, 7)
    model.2  InstanceNorm2d            model.3  ReLU
    model.4  Conv2d(ngf, 2ngf, 3, s2, p1)   model.5/6 norm, relu
    model.7  Conv2d(2ngf, 4ngf, 3, s2, p1)  model.8/9 norm, relu
    model.10 .. model.(10+n-1)  ResnetBlock(4ngf): conv_block.{0 pad, 1 conv,
             2 norm, 3 relu, 4 pad, 5 conv, 6 norm}  (with dropout: a
             Dropout at 4 shifts the second conv to conv_block.6)
    model.(10+n)   ConvTranspose2d(4ngf, 2ngf, 3, s2, p1, output_padding 1)
    model.(10+n+3) ConvTranspose2d(2ngf, ngf, 3, s2, p1, output_padding 1)
    model.(10+n+6) ReflectionPad2d(3)  model.(10+n+7) Conv2d(ngf, out, 7)
    model.(10+n+8) Tanh

so resnet_9blocks has its ConvTransposes at model.19 and model.22 and the
last conv at model.26. Dropout is the identity in test mode, so a
``--use_dropout`` checkpoint exports to the same graph.
"""

from __future__ import annotations

import io
import pickle
import re
import sys
import types
import zipfile
from collections import OrderedDict

import numpy as np

EPS = 1e-5  # torch.nn.InstanceNorm2d's default epsilon
OPSET = 13


class CheckpointError(Exception):
    """A .pth that is not a ResnetGenerator state_dict this code understands."""


# --------------------------------------------------------------------------
# Reading torch's zip format without torch
# --------------------------------------------------------------------------

_DTYPES = {
    "FloatStorage": np.float32,
    "DoubleStorage": np.float64,
    "HalfStorage": np.float16,
    "BFloat16Storage": None,  # refused below: numpy has no bfloat16
    "LongStorage": np.int64,
    "IntStorage": np.int32,
    "ShortStorage": np.int16,
    "CharStorage": np.int8,
    "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}


class _StorageType:
    def __init__(self, name):
        self.name = name


def _rebuild_tensor_v2(storage, storage_offset, size, stride, requires_grad=False,
                       backward_hooks=None, metadata=None):
    """numpy twin of torch._utils._rebuild_tensor_v2 (strides in elements)."""
    flat, itemsize = storage
    size = tuple(int(s) for s in size)
    if not size:
        return flat[storage_offset].copy()
    view = np.lib.stride_tricks.as_strided(
        flat[storage_offset:], shape=size, strides=tuple(int(s) * itemsize for s in stride))
    return np.array(view)  # own the memory, contiguous


def _rebuild_parameter(data, requires_grad=False, backward_hooks=None):
    return data


class _RestrictedUnpickler(pickle.Unpickler):
    """Unpickles a state_dict, resolving only the globals a state_dict uses;
    anything else (arbitrary code in a malicious .pth) is refused."""

    def __init__(self, file, storages):
        super().__init__(file)
        self._storages = storages

    def find_class(self, module, name):
        if module == "collections" and name == "OrderedDict":
            return OrderedDict
        if module == "torch._utils" and name == "_rebuild_tensor_v2":
            return _rebuild_tensor_v2
        if module == "torch._utils" and name == "_rebuild_parameter":
            return _rebuild_parameter
        if module == "torch" and name in _DTYPES:
            return _StorageType(name)
        raise CheckpointError(f"data.pkl refers to {module}.{name}, which a state_dict never needs; refusing to load it")

    def persistent_load(self, pid):
        # torch: ('storage', storage_type, key, location, numel)
        if not (isinstance(pid, tuple) and len(pid) >= 5 and pid[0] == "storage"):
            raise CheckpointError(f"unknown persistent id {pid!r}")
        storage_type, key = pid[1], str(pid[2])
        dtype = _DTYPES.get(getattr(storage_type, "name", ""))
        if dtype is None:
            raise CheckpointError(f"storage {key}: unsupported storage type {getattr(storage_type, 'name', storage_type)}")
        raw = self._storages(key)
        flat = np.frombuffer(raw, dtype=np.dtype(dtype).newbyteorder("<"))
        return (flat, np.dtype(dtype).itemsize)


def read_state_dict(path):
    """Reads a torch.save'd state_dict (zip format) into {key: np.ndarray}."""
    try:
        zf = zipfile.ZipFile(path)
    except zipfile.BadZipFile as e:
        raise CheckpointError(
            f"{path}: not a zip archive ({e}); legacy (pre-1.6) torch.save files are not supported: "
            "re-save with a recent torch or convert elsewhere") from e
    with zf:
        names = zf.namelist()
        pkl = [n for n in names if n.endswith("/data.pkl") or n == "data.pkl"]
        if len(pkl) != 1:
            raise CheckpointError(f"{path}: expected one data.pkl in the archive, found {len(pkl)}")
        prefix = pkl[0][: -len("data.pkl")]
        byteorder = prefix + "byteorder"
        if byteorder in names and zf.read(byteorder).strip() != b"little":
            raise CheckpointError(f"{path}: big-endian checkpoints are not supported")

        def storage(key):
            name = f"{prefix}data/{key}"
            if name not in names:
                raise CheckpointError(f"{path}: storage {name} missing from the archive")
            return zf.read(name)

        obj = _RestrictedUnpickler(io.BytesIO(zf.read(pkl[0])), storage).load()
    if not isinstance(obj, dict):
        raise CheckpointError(f"{path}: data.pkl holds a {type(obj).__name__}, not a state_dict")
    out = OrderedDict()
    for k, v in obj.items():
        if k.startswith("module."):  # saved from a DataParallel wrapper
            k = k[len("module."):]
        out[k] = v
    return out


# --------------------------------------------------------------------------
# Writing torch's zip format without torch (for tests)
# --------------------------------------------------------------------------

def _fake_torch_modules():
    """Module objects named torch / torch._utils so that pickle writes the
    same global references torch.save does (torch.FloatStorage,
    torch._utils._rebuild_tensor_v2). Only the writer uses them."""
    torch = types.ModuleType("torch")
    utils = types.ModuleType("torch._utils")

    class FloatStorage:  # noqa: D401 - a name only
        pass

    FloatStorage.__module__ = "torch"
    FloatStorage.__qualname__ = "FloatStorage"

    def rebuild(*args):  # never called: only its name is pickled
        raise RuntimeError("placeholder")

    rebuild.__module__ = "torch._utils"
    rebuild.__qualname__ = "_rebuild_tensor_v2"
    rebuild.__name__ = "_rebuild_tensor_v2"
    torch.FloatStorage = FloatStorage
    torch._utils = utils
    utils._rebuild_tensor_v2 = rebuild
    return torch, utils


def write_state_dict(path, state_dict, archive="archive"):
    """Writes {key: float32 array} like ``torch.save(state_dict, path)``:
    a stored zip with ``archive/data.pkl`` (pickle protocol 2, tensors as
    ``torch._utils._rebuild_tensor_v2`` over persistent-id storages),
    ``archive/data/N`` raw little-endian storages, ``archive/version`` and
    ``archive/byteorder``."""
    saved = {m: sys.modules.get(m) for m in ("torch", "torch._utils")}
    torch, utils = _fake_torch_modules()
    sys.modules["torch"], sys.modules["torch._utils"] = torch, utils
    try:
        storages = []

        class _Storage:
            def __init__(self, key, numel):
                self.key, self.numel = key, numel

        class _Tensor:
            def __init__(self, arr):
                arr = np.ascontiguousarray(arr, dtype="<f4")
                self.storage = _Storage(str(len(storages)), arr.size)
                storages.append(arr.tobytes())
                self.shape = arr.shape
                self.stride = tuple(s // 4 for s in arr.strides)

            def __reduce_ex__(self, protocol):
                return (utils._rebuild_tensor_v2,
                        (self.storage, 0, self.shape, self.stride, False, OrderedDict()))

        class _Pickler(pickle.Pickler):
            def persistent_id(self, obj):
                if isinstance(obj, _Storage):
                    return ("storage", torch.FloatStorage, obj.key, "cpu", obj.numel)
                return None

        sd = OrderedDict((k, _Tensor(v)) for k, v in state_dict.items())
        # torch's state_dict carries per-module versions in an attribute,
        # which pickle writes as a BUILD of the OrderedDict.
        modules = sorted({k.rsplit(".", 1)[0] for k in state_dict})
        sd._metadata = OrderedDict((m, {"version": 1}) for m in ["", "model", *modules])
        buf = io.BytesIO()
        _Pickler(buf, protocol=2).dump(sd)
    finally:
        for m, v in saved.items():
            if v is None:
                sys.modules.pop(m, None)
            else:
                sys.modules[m] = v
    def entry(name):  # fixed timestamp: same weights, same bytes
        return zipfile.ZipInfo(f"{archive}/{name}", date_time=(1980, 1, 1, 0, 0, 0))

    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED) as zf:
        zf.writestr(entry("data.pkl"), buf.getvalue())
        zf.writestr(entry("byteorder"), "little")
        for i, raw in enumerate(storages):
            zf.writestr(entry(f"data/{i}"), raw)
        zf.writestr(entry("version"), "3\n")


# --------------------------------------------------------------------------
# The generator's layout
# --------------------------------------------------------------------------

def layout(sd):
    """Checks a state_dict against ResnetGenerator and returns
    (ngf, n_blocks, first, downs, blocks, ups, last): parameter-name prefixes
    of each conv in order; blocks is a list of (conv_a, conv_b)."""
    keys = [k for k in sd if not k.endswith(("running_mean", "running_var", "num_batches_tracked"))]
    top = sorted({int(m.group(1)) for k in keys if (m := re.fullmatch(r"model\.(\d+)\.weight", k))})
    blk = sorted({int(m.group(1)) for k in keys if (m := re.match(r"model\.(\d+)\.conv_block\.", k))})
    if not top:
        raise CheckpointError("no model.N.weight keys: not a ResnetGenerator state_dict "
                              f"(first keys: {', '.join(list(sd)[:5])})")
    n = len(blk)
    if top[:3] != [1, 4, 7] or blk != list(range(10, 10 + n)) or top[3:] != [10 + n, 13 + n, 17 + n]:
        raise CheckpointError(
            f"conv layers at model.{top} and ResnetBlocks at model.{blk}: expected convs at "
            f"model.1, 4, 7, {10 + n}, {13 + n}, {17 + n} around {n} blocks at model.10..{9 + n} "
            "(resnet_Nblocks with instance norm and reflect padding)")
    blocks = []
    for b in blk:
        second = 6 if f"model.{b}.conv_block.6.weight" in sd else 5
        blocks.append((f"model.{b}.conv_block.1", f"model.{b}.conv_block.{second}"))
    first = "model.1"
    downs = ["model.4", "model.7"]
    ups = [f"model.{10 + n}", f"model.{13 + n}"]
    last = f"model.{17 + n}"
    w1 = sd[first + ".weight"]
    ngf = w1.shape[0]
    expect = {first: (ngf, 3, 7, 7), downs[0]: (2 * ngf, ngf, 3, 3), downs[1]: (4 * ngf, 2 * ngf, 3, 3),
              ups[0]: (4 * ngf, 2 * ngf, 3, 3), ups[1]: (2 * ngf, ngf, 3, 3), last: (3, ngf, 7, 7)}
    for a, b in blocks:
        expect[a] = expect[b] = (4 * ngf, 4 * ngf, 3, 3)
    for name, shape in expect.items():
        w = sd.get(name + ".weight")
        bias = sd.get(name + ".bias")
        if w is None or tuple(w.shape) != shape:
            raise CheckpointError(f"{name}.weight: shape {None if w is None else tuple(w.shape)}, expected {shape}"
                                  " (3-channel resnet generator)")
        out_ch = shape[1] if name in ups else shape[0]
        if bias is None or tuple(bias.shape) != (out_ch,):
            raise CheckpointError(f"{name}.bias: shape {None if bias is None else tuple(bias.shape)}, "
                                  f"expected ({out_ch},) (instance norm generators have conv biases)")
    return ngf, n, first, downs, blocks, ups, last


# --------------------------------------------------------------------------
# ONNX graph
# --------------------------------------------------------------------------

def build_onnx(sd, name="cyclegan_resnet_generator"):
    """The ONNX model (opset 13) of the generator: input ``input``
    [1, 3, H, W] in [-1, 1], output ``output`` [1, 3, H, W] (tanh), H and W
    dynamic (multiples of 4)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    ngf, n, first, downs, blocks, ups, last = layout(sd)
    nodes, inits = [], []
    counter = [0]

    def fresh(tag):
        counter[0] += 1
        return f"{tag}_{counter[0]}"

    def init(name, arr):
        inits.append(numpy_helper.from_array(np.asarray(arr), name))
        return name

    for prefix in [first, *downs, *[c for ab in blocks for c in ab], *ups, last]:
        init(prefix + ".weight", sd[prefix + ".weight"].astype(np.float32))
        init(prefix + ".bias", sd[prefix + ".bias"].astype(np.float32))
    pads = {p: init(f"reflect_pads_{p}", np.array([0, 0, p, p, 0, 0, p, p], np.int64)) for p in (1, 3)}
    norm_params = {}

    def reflect(x, p):
        y = fresh("pad")
        nodes.append(helper.make_node("Pad", [x, pads[p]], [y], mode="reflect"))
        return y

    def conv(x, prefix, k, stride=1, pad=0):
        y = fresh("conv")
        nodes.append(helper.make_node("Conv", [x, prefix + ".weight", prefix + ".bias"], [y],
                                      kernel_shape=[k, k], strides=[stride, stride], pads=[pad] * 4))
        return y

    def deconv(x, prefix):
        y = fresh("deconv")
        nodes.append(helper.make_node("ConvTranspose", [x, prefix + ".weight", prefix + ".bias"], [y],
                                      kernel_shape=[3, 3], strides=[2, 2], pads=[1, 1, 1, 1],
                                      output_padding=[1, 1]))
        return y

    def norm(x, ch):
        if ch not in norm_params:  # affine=False: scale 1, bias 0
            norm_params[ch] = (init(f"in_scale_{ch}", np.ones(ch, np.float32)),
                               init(f"in_bias_{ch}", np.zeros(ch, np.float32)))
        s, b = norm_params[ch]
        y = fresh("norm")
        nodes.append(helper.make_node("InstanceNormalization", [x, s, b], [y], epsilon=EPS))
        return y

    def relu(x):
        y = fresh("relu")
        nodes.append(helper.make_node("Relu", [x], [y]))
        return y

    x = relu(norm(conv(reflect("input", 3), first, 7), ngf))
    x = relu(norm(conv(x, downs[0], 3, 2, 1), 2 * ngf))
    x = relu(norm(conv(x, downs[1], 3, 2, 1), 4 * ngf))
    for a, b in blocks:
        h = relu(norm(conv(reflect(x, 1), a, 3), 4 * ngf))
        h = norm(conv(reflect(h, 1), b, 3), 4 * ngf)
        y = fresh("add")
        nodes.append(helper.make_node("Add", [x, h], [y]))
        x = y
    x = relu(norm(deconv(x, ups[0]), 2 * ngf))
    x = relu(norm(deconv(x, ups[1]), ngf))
    x = conv(reflect(x, 3), last, 7)
    nodes.append(helper.make_node("Tanh", [x], ["output"]))
    graph = helper.make_graph(
        nodes, name,
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, [1, 3, "H", "W"])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, 3, "H", "W"])],
        inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="murk scripts/cyclegan_onnx.py")
    model.ir_version = 8  # readable by onnxruntime >= 1.14 and tract
    onnx.checker.check_model(model)
    return model


# --------------------------------------------------------------------------
# numpy forward pass (float64), written from the layer definitions, not
# from the ONNX graph
# --------------------------------------------------------------------------

def _reflect(x, p):
    return np.pad(x, ((0, 0), (p, p), (p, p)), mode="reflect")


def _conv(x, w, b, stride=1, pad=0):
    if pad:
        x = np.pad(x, ((0, 0), (pad, pad), (pad, pad)))
    _, h, wd = x.shape
    k = w.shape[2]
    ho, wo = (h - k) // stride + 1, (wd - k) // stride + 1
    out = np.zeros((w.shape[0], ho, wo))
    for i in range(k):
        for j in range(k):
            patch = x[:, i:i + stride * (ho - 1) + 1:stride, j:j + stride * (wo - 1) + 1:stride]
            out += np.tensordot(w[:, :, i, j], patch, axes=(1, 0))
    return out + b[:, None, None]


def _deconv(x, w, b, stride=2, pad=1, output_padding=1):
    """Transposed conv by scattering each input pixel's kernel."""
    cin, h, wd = x.shape
    k = w.shape[2]
    full = np.zeros((w.shape[1], (h - 1) * stride + k + output_padding, (wd - 1) * stride + k + output_padding))
    for i in range(k):
        for j in range(k):
            full[:, i:i + stride * (h - 1) + 1:stride, j:j + stride * (wd - 1) + 1:stride] += \
                np.tensordot(w[:, :, i, j], x, axes=(0, 0))
    ho = (h - 1) * stride - 2 * pad + k + output_padding
    wo = (wd - 1) * stride - 2 * pad + k + output_padding
    return full[:, pad:pad + ho, pad:pad + wo] + b[:, None, None]


def _norm(x):
    m = x.mean(axis=(1, 2), keepdims=True)
    v = ((x - m) ** 2).mean(axis=(1, 2), keepdims=True)
    return (x - m) / np.sqrt(v + EPS)


def numpy_forward(sd, x):
    """Runs the generator on x [3, H, W] (values in [-1, 1], H and W
    multiples of 4) in float64; returns [3, H, W]."""
    _, _, first, downs, blocks, ups, last = layout(sd)
    p = {k: v.astype(np.float64) for k, v in sd.items()}
    relu = lambda t: np.maximum(t, 0.0)  # noqa: E731
    x = np.asarray(x, np.float64)
    x = relu(_norm(_conv(_reflect(x, 3), p[first + ".weight"], p[first + ".bias"])))
    for d in downs:
        x = relu(_norm(_conv(x, p[d + ".weight"], p[d + ".bias"], 2, 1)))
    for a, b in blocks:
        h = relu(_norm(_conv(_reflect(x, 1), p[a + ".weight"], p[a + ".bias"])))
        h = _norm(_conv(_reflect(h, 1), p[b + ".weight"], p[b + ".bias"]))
        x = x + h
    for u in ups:
        x = relu(_norm(_deconv(x, p[u + ".weight"], p[u + ".bias"])))
    return np.tanh(_conv(_reflect(x, 3), p[last + ".weight"], p[last + ".bias"]))


def random_state_dict(ngf, n_blocks, seed, dropout=False):
    """A ResnetGenerator state_dict with random weights (std 1/sqrt(fan_in),
    so the tanh output spans its range instead of sitting at 0)."""
    rng = np.random.default_rng(seed)
    sd = OrderedDict()

    def put(name, out_ch, in_ch, k, transpose=False):
        shape = (in_ch, out_ch, k, k) if transpose else (out_ch, in_ch, k, k)
        sd[name + ".weight"] = (rng.standard_normal(shape) / np.sqrt(in_ch * k * k)).astype(np.float32)
        sd[name + ".bias"] = (0.1 * rng.standard_normal(out_ch)).astype(np.float32)

    put("model.1", ngf, 3, 7)
    put("model.4", 2 * ngf, ngf, 3)
    put("model.7", 4 * ngf, 2 * ngf, 3)
    for b in range(n_blocks):
        put(f"model.{10 + b}.conv_block.1", 4 * ngf, 4 * ngf, 3)
        put(f"model.{10 + b}.conv_block.{6 if dropout else 5}", 4 * ngf, 4 * ngf, 3)
    put(f"model.{10 + n_blocks}", 2 * ngf, 4 * ngf, 3, transpose=True)
    put(f"model.{13 + n_blocks}", ngf, 2 * ngf, 3, transpose=True)
    put(f"model.{17 + n_blocks}", 3, ngf, 7)
    return sd
