#!/usr/bin/env python3
"""Convert Booster Robotics' T1 walking policy into the files Strata ships.

Reads the TorchScript archive T1.pt and the deployment configuration T1.yaml (booster_gym,
deploy/models/T1.pt and deploy/configs/T1.yaml) and writes, into crates/rcssmj/assets/t1/:

- t1.safetensors: the four linear layers' weights and biases, float32, under the names
  PyTorch gives them in the nn.Sequential state dict ("0.weight", "0.bias", "2.weight", ...),
  so a retrained policy exported with safetensors.torch.save_file loads the same way;
- t1.toml: the deployment constants (joint order, default pose, gains, torque limits, gait
  frequency, observation scales, action scale and clip, control period, command smoothing).

Neither torch nor PyYAML is needed: the archive is a zip whose data.pkl pickle names each
tensor's storage, offset, shape and strides (read with an Unpickler that stubs torch's classes),
and the configuration is the small YAML subset parsed below. Numbers are copied unchanged and
the output is byte-for-byte the same on every run.

Usage: scripts/convert-t1-policy.py [SOURCE_DIR] [OUTPUT_DIR]
  SOURCE_DIR defaults to /work/shared/third_party/booster_t1, OUTPUT_DIR to
  crates/rcssmj/assets/t1 beside this script's repository.
"""

import io
import json
import math
import pickle
import re
import struct
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DEFAULT_SOURCE = Path("/work/shared/third_party/booster_t1")
DEFAULT_OUTPUT = REPO / "crates" / "rcssmj" / "assets" / "t1"

# The network the Rust side implements: Linear, ELU, Linear, ELU, Linear, ELU, Linear.
EXPECTED_LAYERS = ["Linear", "ELU", "Linear", "ELU", "Linear", "ELU", "Linear"]
OBSERVATIONS = 47
ACTIONS = 12

# The T1's 23 joints in the order of the deployment arrays (the Booster SDK's joint index):
# head, left arm, right arm, waist, left leg, right leg. The YAML has the numbers but no names.
JOINT_NAMES = [
    "head_yaw", "head_pitch",
    "left_shoulder_pitch", "left_shoulder_roll", "left_elbow_pitch", "left_elbow_yaw",
    "right_shoulder_pitch", "right_shoulder_roll", "right_elbow_pitch", "right_elbow_yaw",
    "waist_yaw",
    "left_hip_pitch", "left_hip_roll", "left_hip_yaw",
    "left_knee_pitch", "left_ankle_pitch", "left_ankle_roll",
    "right_hip_pitch", "right_hip_roll", "right_hip_yaw",
    "right_knee_pitch", "right_ankle_pitch", "right_ankle_roll",
]

# From booster_gym deploy/utils/policy.py, not the YAML: below this norm of the smoothed
# command the deployment sets the gait frequency to zero (standing).
STANDING_COMMAND_NORM = 1e-5


class ConversionError(Exception):
    pass


# --- T1.pt ------------------------------------------------------------------------------------


class _Stub:
    """Any TorchScript module class in the pickle: keeps its attributes, remembers its name."""

    def __setstate__(self, state):
        self.__dict__.update(state)


class _TensorRecord:
    def __init__(self, storage, offset, size, stride):
        self.storage = storage
        self.offset = offset
        self.size = tuple(size)
        self.stride = tuple(stride)


def _rebuild_tensor_v2(storage, storage_offset, size, stride, requires_grad=False,
                       backward_hooks=None, metadata=None):
    return _TensorRecord(storage, storage_offset, size, stride)


class _FloatStorage:
    pass


class _ArchiveUnpickler(pickle.Unpickler):
    """Resolves only the names a TorchScript state pickle uses; anything else is an error."""

    def find_class(self, module, name):
        if module == "torch._utils" and name == "_rebuild_tensor_v2":
            return _rebuild_tensor_v2
        if module == "torch" and name == "FloatStorage":
            return _FloatStorage
        if module == "collections" and name == "OrderedDict":
            return dict
        if module.startswith("__torch__."):
            return type(name, (_Stub,), {"torch_class": f"{module}.{name}"})
        raise ConversionError(f"T1.pt data.pkl: unexpected class {module}.{name}")

    def persistent_load(self, pid):
        # ('storage', storage type, key, location, number of elements)
        if not (isinstance(pid, tuple) and len(pid) == 5 and pid[0] == "storage"):
            raise ConversionError(f"T1.pt data.pkl: unexpected persistent id {pid!r}")
        _, storage_type, key, _location, numel = pid
        if storage_type is not _FloatStorage:
            raise ConversionError(f"T1.pt: storage {key} is not float32")
        return (str(key), int(numel))


def _strided_values(record, storage_values):
    """The tensor's elements in row-major order, following its offset and strides."""
    out = []

    def walk(dim, base):
        if dim == len(record.size):
            out.append(storage_values[base])
            return
        for i in range(record.size[dim]):
            walk(dim + 1, base + i * record.stride[dim])

    walk(0, record.offset)
    return out


def read_network(pt_path):
    try:
        return _read_network(pt_path)
    except (KeyError, zipfile.BadZipFile, pickle.UnpicklingError, EOFError, struct.error) as err:
        raise ConversionError(f"{pt_path}: not a readable TorchScript archive: {err}") from None


def _read_network(pt_path):
    with zipfile.ZipFile(pt_path) as archive:
        names = archive.namelist()
        prefix = names[0].split("/", 1)[0]
        byteorder = archive.read(f"{prefix}/byteorder").decode().strip()
        if byteorder != "little":
            raise ConversionError(f"{pt_path}: byte order {byteorder!r}, expected little")
        model = _ArchiveUnpickler(io.BytesIO(archive.read(f"{prefix}/data.pkl"))).load()
        kinds = [type(model.__dict__[str(i)]).__name__ for i in range(len(EXPECTED_LAYERS))]
        if kinds != EXPECTED_LAYERS or str(len(EXPECTED_LAYERS)) in model.__dict__:
            raise ConversionError(f"{pt_path}: layers {kinds}, expected {EXPECTED_LAYERS}")
        _check_elu_alpha(archive, prefix, pt_path)

        tensors = []
        for index, kind in enumerate(EXPECTED_LAYERS):
            if kind != "Linear":
                continue
            layer = model.__dict__[str(index)]
            for part in ("weight", "bias"):
                record = getattr(layer, part)
                key, numel = record.storage
                raw = archive.read(f"{prefix}/data/{key}")
                if len(raw) != 4 * numel:
                    raise ConversionError(
                        f"{pt_path}: storage {key} holds {len(raw)} bytes, expected {4 * numel}"
                    )
                values = struct.unpack(f"<{numel}f", raw)
                tensors.append((f"{index}.{part}", record.size, _strided_values(record, values)))
    _check_chain(tensors, pt_path)
    return tensors


def _check_elu_alpha(archive, prefix, pt_path):
    # alpha is a compile-time constant of the scripted ELU class, so it lives in its code.
    code = archive.read(f"{prefix}/code/__torch__/torch/nn/modules/activation.py").decode()
    match = re.search(r"alpha : Final\[float\] = ([0-9.eE+-]+)", code)
    if match is None or float(match.group(1)) != 1.0:
        raise ConversionError(f"{pt_path}: ELU alpha is not 1")


def _check_chain(tensors, pt_path):
    width = OBSERVATIONS
    for i in range(0, len(tensors), 2):
        (wname, wshape, _), (bname, bshape, _) = tensors[i], tensors[i + 1]
        if len(wshape) != 2 or wshape[1] != width or bshape != (wshape[0],):
            raise ConversionError(f"{pt_path}: {wname} {wshape}, {bname} {bshape} break the chain")
        width = wshape[0]
    if width != ACTIONS:
        raise ConversionError(f"{pt_path}: the network outputs {width} values, expected {ACTIONS}")


def safetensors_bytes(tensors):
    header = {"__metadata__": {
        "format": "pt",
        "source": "booster_gym deploy/models/T1.pt @ da396a06d6eed99e2de72d7749c48ee8748950f9",
    }}
    payload = bytearray()
    for name, shape, values in tensors:
        start = len(payload)
        payload += struct.pack(f"<{len(values)}f", *values)
        header[name] = {"dtype": "F32", "shape": list(shape), "data_offsets": [start, len(payload)]}
    text = json.dumps(header, sort_keys=True, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 8)  # the format pads the header to 8-byte alignment with spaces
    return struct.pack("<Q", len(text)) + text + bytes(payload)


# --- T1.yaml ----------------------------------------------------------------------------------


def parse_simple_yaml(text, path):
    """Nested mappings by indentation, scalars, and flow lists that may span lines."""
    root = {}
    stack = [(-1, root)]
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        line = lines[i].split("#", 1)[0].rstrip()
        i += 1
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        key, sep, rest = line.strip().partition(":")
        if not sep:
            raise ConversionError(f"{path}:{i}: expected `key: value`")
        while stack[-1][0] >= indent:
            stack.pop()
        parent = stack[-1][1]
        rest = rest.strip()
        if rest == "":
            parent[key] = {}
            stack.append((indent, parent[key]))
        elif rest.startswith("["):
            while "]" not in rest:
                if i >= len(lines):
                    raise ConversionError(f"{path}: list `{key}` is not closed")
                rest += " " + lines[i].split("#", 1)[0].strip()
                i += 1
            items = [s.strip() for s in rest[1:rest.index("]")].split(",")]
            parent[key] = [_scalar(s, path, key) for s in items if s]
        else:
            parent[key] = _scalar(rest, path, key)
    return root


def _scalar(text, path, key):
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    try:
        return int(text)
    except ValueError:
        pass
    try:
        return float(text)
    except ValueError:
        raise ConversionError(f"{path}: `{key}`: cannot read {text!r}") from None


def _get(config, dotted, path):
    node = config
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            raise ConversionError(f"{path}: missing `{dotted}`")
        node = node[part]
    return node


def _number(value):
    """TOML float text that round-trips the YAML value exactly."""
    value = float(value)
    if not math.isfinite(value):
        raise ConversionError(f"non-finite value {value}")
    return repr(value)


def config_toml(yaml_path):
    config = parse_simple_yaml(yaml_path.read_text(), yaml_path)
    arrays = {
        name: _get(config, f"common.{name}", yaml_path)
        for name in ("default_qpos", "stiffness", "damping", "torque_limit")
    }
    for name, values in arrays.items():
        if len(values) != len(JOINT_NAMES):
            raise ConversionError(f"{yaml_path}: common.{name} has {len(values)} values, expected 23")
    if _get(config, "policy.num_observations", yaml_path) != OBSERVATIONS:
        raise ConversionError(f"{yaml_path}: policy.num_observations is not {OBSERVATIONS}")
    if _get(config, "policy.num_actions", yaml_path) != ACTIONS:
        raise ConversionError(f"{yaml_path}: policy.num_actions is not {ACTIONS}")
    dt = float(_get(config, "common.dt", yaml_path))
    decimation = int(_get(config, "policy.control.decimation", yaml_path))
    norm = lambda key: _number(_get(config, f"policy.normalization.{key}", yaml_path))  # noqa: E731

    out = [
        "# Booster T1 walking policy: deployment constants.",
        "# Converted from booster_gym deploy/configs/T1.yaml (commit",
        "# da396a06d6eed99e2de72d7749c48ee8748950f9) by scripts/convert-t1-policy.py; numbers unchanged.",
        "# Units: rad, rad/s, s, Hz, N m/rad (stiffness), N m s/rad (damping), N m (torque limit).",
        "",
        "[control]",
        "# The deployment's low-level step and how many of them make one policy step.",
        f"dt = {_number(dt)}",
        f"decimation = {decimation}",
        "# The most the smoothed walk command moves toward the desired one per policy step, in",
        "# m/s (rad/s for yaw): the deployment clips the change to the policy period's value.",
        f"command_smoothing_step = {_number(dt * decimation)}",
        "",
        "[gait]",
        "# Hz while walking; zero (standing) while the smoothed command's norm is below",
        "# standing_command_norm (deploy/utils/policy.py).",
        f"frequency = {_number(_get(config, 'policy.gait_frequency', yaml_path))}",
        f"standing_command_norm = {_number(STANDING_COMMAND_NORM)}",
        "",
        "[observation_scales]",
        f"gravity = {norm('gravity')}",
        f"lin_vel = {norm('lin_vel')}",
        f"ang_vel = {norm('ang_vel')}",
        f"dof_pos = {norm('dof_pos')}",
        f"dof_vel = {norm('dof_vel')}",
        "",
        "[action]",
        "# Leg joint target = default position + scale * clip(action, -clip, clip).",
        f"scale = {_number(_get(config, 'policy.control.action_scale', yaml_path))}",
        f"clip = {norm('clip_actions')}",
    ]
    out.append("")
    out.append("# The 23 joints in the deployment's order; the last 12 (the legs) are the policy's.")
    for index, name in enumerate(JOINT_NAMES):
        out += [
            "",
            "[[joints]]",
            f'name = "{name}"',
            f"default_position = {_number(arrays['default_qpos'][index])}",
            f"stiffness = {_number(arrays['stiffness'][index])}",
            f"damping = {_number(arrays['damping'][index])}",
            f"torque_limit = {_number(arrays['torque_limit'][index])}",
        ]
    return "\n".join(out) + "\n"


def main(argv):
    source = Path(argv[1]) if len(argv) > 1 else DEFAULT_SOURCE
    output = Path(argv[2]) if len(argv) > 2 else DEFAULT_OUTPUT
    try:
        tensors = read_network(source / "T1.pt")
        toml_text = config_toml(source / "T1.yaml")
    except (ConversionError, OSError) as err:
        print(f"convert-t1-policy: {err}", file=sys.stderr)
        return 1
    output.mkdir(parents=True, exist_ok=True)
    (output / "t1.safetensors").write_bytes(safetensors_bytes(tensors))
    (output / "t1.toml").write_text(toml_text)
    for name, shape, _ in tensors:
        print(f"{name}: {list(shape)}")
    print(f"wrote {output / 't1.safetensors'} and {output / 't1.toml'}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
