"""Reads a nuno .safetensors file with Python's safetensors package.

Usage: safetensors_check.py FILE OUT.json -> {name: [shape, sum of values]}
"""

import json
import sys

from safetensors.numpy import load_file

tensors = load_file(sys.argv[1])
report = {name: [list(t.shape), float(t.astype("float64").sum())] for name, t in tensors.items()}
with open(sys.argv[2], "w") as f:
    json.dump(report, f)
