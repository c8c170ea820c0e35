"""schemathesis hooks for the contract run (tests/python/contract.py).

Two things a JSON schema cannot state, and only these, are set aside:
- binary bodies (`application/octet-stream`: safetensors, KServe's binary
  tensor extension) are byte formats; tests/server.rs and the KServe client
  test cover them, so generated cases use JSON only;
- row widths are the model's (`obs_dim`, `act_dim`, stated in each route's
  description), and some sizes are relations between fields (as many action
  rows as states, `horizon` actions per start, KServe's `data` holding
  shape's product of numbers), and a cost term's observation is one of the
  model's (by name or index). Schema-valid cases get the model's widths and
  matching sizes (a plan's `state` too, cost terms an index the model has)
  before they are sent, so the server's other rules are what
  they meet; a 422 naming a width, such a relation, a CVaR level α the
  model's threshold table lacks, (asked with `clip: false`) an action
  outside the model's action box, or a plan session continued at another
  horizon than it was opened with (a relation with an earlier answer) is not counted.
Every other failure of `--checks all` fails the run.
"""

import json
import os
import re

import schemathesis

OBS_DIM = int(os.environ["NUNO_OBS_DIM"])
ACT_DIM = int(os.environ["NUNO_ACT_DIM"])

# 422 messages that name a model-dependent width or a KServe shape/data relation.
SCHEMA_CANNOT_STATE = [
    re.compile(r"has \d+ entries, this model expects \d+"),
    re.compile(r"`states` has \d+ rows but `actions` has \d+"),
    re.compile(r"`actions` has \d+ sequences for \d+ start states"),
    re.compile(r"`actions\[\d+\]` has \d+ steps, the horizon is \d+"),
    # `score`: candidates per start, and each candidate's steps.
    re.compile(r"`actions` has candidates for \d+ start states, `states` has \d+"),
    re.compile(r"`actions\[\d+\]` has \d+ candidates, `actions\[0\]` has \d+"),
    re.compile(r"`(shared_actions|actions\[\d+\])\[\d+\]` has \d+ steps, the horizon is \d+"),
    re.compile(r"input `\w+` has shape \[[^\]]*\] but \d+ values; expected \[\d+, \d+\]"),
    re.compile(r"`\w+` has \d+ values, not a whole number of rows of width \d+"),
    re.compile(r"`states` and `actions` differ in rows"),
    # The CVaR thresholds ε(h, α) a model has are the model's (its `thresholds`).
    re.compile(r"the model has no ε\(h = \d+, α = [^)]*\); its table covers"),
    # The action box is the model's (`GET /v1/models/{id}`); `clip: false` asks for the 422.
    re.compile(r"is outside the action box \[[^\]]*\] \(send `clip: true`"),
    # A plan session keeps the model and horizon of the call that opened it:
    # a relation with an earlier answer, which a stateful link may break.
    re.compile(r"session `\w+` plans for model `[^`]*` at horizon \d+, not `[^`]*` at \d+"),
]


@schemathesis.hook
def filter_case(context, case):
    return case.media_type != "application/octet-stream"


def _rows(rows, width):
    """`rows` with each row cut or padded (with zeros) to `width`."""
    if not isinstance(rows, list):
        return rows
    fixed = []
    for row in rows:
        if isinstance(row, list):
            row = (row + [0.0] * width)[:width]
        fixed.append(row)
    return fixed


def _sized(rows, count, filler):
    """`rows` cut or repeated to `count` entries."""
    if not isinstance(rows, list) or not isinstance(count, int) or count < 1:
        return rows
    return (rows + [filler] * count)[:count] if rows else [filler] * count


@schemathesis.hook
def map_case(context, case):
    """Schema-valid JSON bodies get the model's widths and matching sizes."""
    body = case.body
    positive = case.meta is not None and case.meta.generation.mode == "positive"
    if not positive or not isinstance(body, dict):
        return case
    path = case.operation.path
    cost = body.get("cost")
    if isinstance(cost, dict) and isinstance(cost.get("terms"), list):
        for term in cost["terms"]:
            if isinstance(term, dict) and "observation" in term:
                index = term["observation"]
                term["observation"] = int(index) % OBS_DIM if isinstance(index, (int, float)) else 0
    if "states" in body:
        body["states"] = _rows(body["states"], OBS_DIM)
    states = body.get("states")
    batch = len(states) if isinstance(states, list) else None
    actions = body.get("actions")
    if path.endswith("/step") and isinstance(actions, list):
        body["actions"] = _rows(_sized(actions, batch, [0.0] * ACT_DIM), ACT_DIM)
    elif path.endswith("/plan") and isinstance(body.get("state"), list):
        body["state"] = (body["state"] + [0.0] * OBS_DIM)[:OBS_DIM]
    elif path.endswith("/validate"):
        body["actions"] = _rows(actions, ACT_DIM)
    elif path.endswith("/score"):
        horizon = body.get("horizon")
        steps = horizon if isinstance(horizon, int) else 0
        sequence = [[0.0] * ACT_DIM] * steps

        def candidates(sequences, count):
            return [_rows(_sized(c, steps, [0.0] * ACT_DIM), ACT_DIM) for c in _sized(sequences, count, sequence)]

        if isinstance(actions, list):
            first = actions[0] if actions and isinstance(actions[0], list) else []
            count = max(len(first), 1)
            body["actions"] = [candidates(c, count) for c in _sized(actions, batch, [sequence])]
        shared = body.get("shared_actions")
        if isinstance(shared, list):
            body["shared_actions"] = candidates(shared, len(shared))
    elif path.endswith("/rollout") and isinstance(actions, list):
        horizon = body.get("horizon")
        sequence = [[0.0] * ACT_DIM] * (horizon if isinstance(horizon, int) else 0)
        body["actions"] = [
            _rows(_sized(s, horizon, [0.0] * ACT_DIM), ACT_DIM)
            for s in _sized(actions, batch, sequence)
        ]
    return case


def _message(response):
    try:
        error = json.loads(response.content)["error"]
    except (ValueError, KeyError, TypeError):
        return None
    return error["message"] if isinstance(error, dict) else error


@schemathesis.hook
def filter_failure(context, failure, case, response):
    """Keep every failure except a 422 for a width or shape relation."""
    if failure.code != "ST202" or response is None or response.status_code != 422:
        return True
    message = _message(response) or ""
    return not any(pattern.search(message) for pattern in SCHEMA_CANNOT_STATE)
