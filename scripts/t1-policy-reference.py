#!/usr/bin/env python3
"""Reference outputs of the T1 walking network, computed from the ORIGINAL T1.pt with numpy.

Writes crates/rcssmj/tests/data/policy/t1_reference.json: fixed pseudo-random observations
(fixed seed) and the network's raw output (before clipping) for each, computed in float64 from
the float32 weights. The Rust test tests/policy_reference.rs loads the shipped
assets/t1/t1.safetensors and must match within 1e-5, which checks the conversion and the Rust
forward pass together.

The tensors are read independently of the converter's gather: the converter's Unpickler gives
each tensor's storage key, offset, shape and strides, and numpy's as_strided applies them.

Usage: scripts/t1-policy-reference.py [SOURCE_DIR]   (numpy required; no torch)
"""

import importlib.util
import io
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
OUTPUT = REPO / "crates" / "rcssmj" / "tests" / "data" / "policy" / "t1_reference.json"
SEED = 20251223
CASES = 10


def load_converter():
    spec = importlib.util.spec_from_file_location(
        "convert_t1_policy", REPO / "scripts" / "convert-t1-policy.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_layers(pt_path, converter):
    with zipfile.ZipFile(pt_path) as archive:
        model = converter._ArchiveUnpickler(io.BytesIO(archive.read("T1/data.pkl"))).load()
        layers = []
        for index in ("0", "2", "4", "6"):
            layer = model.__dict__[index]
            params = []
            for part in ("weight", "bias"):
                record = getattr(layer, part)
                key, _numel = record.storage
                storage = np.frombuffer(archive.read(f"T1/data/{key}"), dtype="<f4")
                view = np.lib.stride_tricks.as_strided(
                    storage[record.offset:],
                    shape=record.size,
                    strides=[s * 4 for s in record.stride],
                )
                params.append(np.array(view, dtype=np.float64))
            layers.append(tuple(params))
    return layers


def forward(layers, observation):
    x = observation.astype(np.float64)
    for i, (weight, bias) in enumerate(layers):
        x = weight @ x + bias
        if i < len(layers) - 1:
            x = np.where(x > 0.0, x, np.expm1(x))  # ELU, alpha 1
    return x


def observations(rng):
    """Plausible observations laid out as the policy builds them, plus two edge cases."""
    out = [np.zeros(47, dtype=np.float32)]
    for _ in range(CASES - 2):
        obs = np.zeros(47, dtype=np.float32)
        gravity = np.array([0.0, 0.0, -1.0]) + rng.normal(0.0, 0.15, 3)
        obs[0:3] = gravity / np.linalg.norm(gravity)
        obs[3:6] = rng.normal(0.0, 0.6, 3)
        obs[6:9] = rng.uniform(-0.8, 0.8, 3)
        phase = rng.uniform(0.0, 1.0)
        obs[9:11] = [np.cos(2 * np.pi * phase), np.sin(2 * np.pi * phase)]
        obs[11:23] = rng.normal(0.0, 0.2, 12)
        obs[23:35] = rng.normal(0.0, 0.3, 12)
        obs[35:47] = rng.uniform(-1.0, 1.0, 12)
        out.append(obs)
    # Large inputs drive many units deep into ELU's negative branch and the output past the clip.
    out.append(rng.normal(0.0, 3.0, 47).astype(np.float32))
    return out


def main(argv):
    source = Path(argv[1]) if len(argv) > 1 else Path("/work/shared/third_party/booster_t1")
    converter = load_converter()
    layers = read_layers(source / "T1.pt", converter)
    rng = np.random.default_rng(SEED)
    cases = []
    for obs in observations(rng):
        obs = obs.astype(np.float32)
        action = forward(layers, obs)
        cases.append({
            "observation": [float(v) for v in obs],
            "action": [float(v) for v in action],
        })
    fixture = {
        "what": "T1 walking network: raw output (before clipping) for fixed observations",
        "source": "booster_gym deploy/models/T1.pt @ da396a06d6eed99e2de72d7749c48ee8748950f9",
        "regenerate": "python3 scripts/t1-policy-reference.py (numpy)",
        "seed": SEED,
        "cases": cases,
    }
    OUTPUT.parent.mkdir(parents=True, exist_ok=True)
    OUTPUT.write_text(json.dumps(fixture, indent=1) + "\n")
    print(f"wrote {len(cases)} cases to {OUTPUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
