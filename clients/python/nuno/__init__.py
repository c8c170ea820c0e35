"""nuno's Python client: `Client(base_url)` calls a nuno model server with
numpy arrays in and out (`step`, `rollout`, `score`, `plan`, `act`,
`evaluate`, `models`, `model`); every refused request raises `NunoError` with the server's code and
message. The generated low-level client (every route, typed) is
`nuno._generated`, regenerated from the committed spec by `generate.py`."""
from .client import Client, Rollout, Scores, Step
from .errors import NunoError

__all__ = ["Client", "NunoError", "Rollout", "Scores", "Step"]
