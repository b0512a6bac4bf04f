"""The seeded weights of a golden file written as an official checkpoint (``.pth``), without torch.

A seeded golden file (``../shared/golden/*_seeded.activations.safetensors``) lists every key and
shape of the official state dict in its metadata; ``seeded_weights.py`` beside it states the
arithmetic that rebuilds each tensor. ``write_pth`` writes the rebuilt state dict as ``torch.save``
of a ``DataParallel`` model's ``state_dict()`` does (keys under ``module.``): a zip archive with the
pickle ``archive/data.pkl`` (protocol 2; an ``OrderedDict`` of ``torch._utils._rebuild_tensor_v2``
calls) and one float32 storage per tensor, ``archive/data/N``."""

import importlib.util
import json
import struct
import zipfile

import numpy as np


def _seeded_module(golden_dir):
    spec = importlib.util.spec_from_file_location("seeded_weights", golden_dir / "seeded_weights.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def golden_state_dict(golden):
    """[(key, float32 array)] of a seeded golden file, in its metadata's order."""
    seeded = _seeded_module(golden.parent).seeded
    raw = golden.read_bytes()
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8 : 8 + n])
    meta = header["__metadata__"]
    aliases, kept, salt = json.loads(meta["aliases"]), json.loads(meta["kept"]), meta.get("salt", "")
    built = {}
    for key, shape in json.loads(meta["keys"]):
        if key in aliases:
            value = built[aliases[key]]
        elif key in kept:
            entry = header[f"state.{key}"]
            start, end = entry["data_offsets"]
            value = np.frombuffer(raw[8 + n + start : 8 + n + end], dtype="<f4").reshape(shape)
        else:
            value = seeded(key, shape, salt)
        built[key] = value
    return list(built.items())


def _text(s):
    data = s.encode()
    return b"X" + struct.pack("<I", len(data)) + data


def _int(v):
    return b"J" + struct.pack("<i", v)


def _ints(values):
    return b"(" + b"".join(_int(v) for v in values) + b"t"


_ORDERED_DICT = b"ccollections\nOrderedDict\n)R"


def write_pth(state, path, prefix="module."):
    """Writes [(key, array)] as an official ``.pth``, each key under ``prefix``."""
    pickle = [b"\x80\x02", _ORDERED_DICT, b"("]
    for i, (key, value) in enumerate(state):
        shape = list(value.shape)
        strides = [int(np.prod(shape[d + 1 :])) for d in range(len(shape))]
        storage = b"(" + _text("storage") + b"ctorch\nFloatStorage\n" + _text(str(i)) + _text("cpu") + _int(value.size) + b"tQ"
        pickle += [
            _text(prefix + key),
            b"ctorch._utils\n_rebuild_tensor_v2\n(",
            storage,
            _int(0),
            _ints(shape),
            _ints(strides),
            b"\x89",
            _ORDERED_DICT,
            b"tR",
        ]
    pickle += [b"u."]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as z:
        z.writestr("archive/data.pkl", b"".join(pickle))
        z.writestr("archive/byteorder", b"little")
        for i, (_, value) in enumerate(state):
            z.writestr(f"archive/data/{i}", np.ascontiguousarray(value, dtype="<f4").tobytes())
        z.writestr("archive/version", b"3\n")
