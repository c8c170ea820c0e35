"""Regenerates `nuno/_generated`, the low-level client, from the committed
OpenAPI spec with openapi-python-client (the version tests/python/requirements.txt
pins), so the typed request and answer models are the server's own.

usage: python generate.py [OUT_DIR]   (default: nuno/_generated next to this file)
"""
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

here = Path(__file__).resolve().parent
spec = here.parents[1] / "openapi" / "openapi.json"
out = Path(sys.argv[1]) if len(sys.argv) > 1 else here / "nuno" / "_generated"
generator = Path(sys.executable).parent / "openapi-python-client"

with tempfile.TemporaryDirectory() as work:
    config = Path(work) / "config.yml"
    config.write_text("post_hooks: []\n")
    target = Path(work) / "client"
    subprocess.run(
        [str(generator), "generate", "--path", str(spec), "--meta", "none",
         "--output-path", str(target), "--config", str(config)],
        check=True, capture_output=True,
    )
    # openapi-python-client 0.29.1 annotates bodies with two content types
    # (step, score: JSON or safetensors) with `Unset` without importing it.
    imported = re.compile(r"^(from \S+ import .*\bUnset\b|class Unset\b)", re.MULTILINE)
    for module in target.rglob("*.py"):
        text = module.read_text()
        if re.search(r"\bUnset\b", text) and not imported.search(text):
            depth = len(module.relative_to(target).parts) - 1
            line = f"from {'.' * (depth + 1)}types import Unset\n"
            future = "from __future__ import annotations\n"
            if future in text:
                text = text.replace(future, future + line, 1)
            else:
                text = line + text
            module.write_text(text)
    if out.exists():
        shutil.rmtree(out)
    shutil.copytree(target, out)
