//! The OpenAPI 3.1 document, generated from the router itself (each route's
//! path and method come from its handler's `#[utoipa::path]`, registered with
//! `utoipa_axum::routes!`), completed with what every route shares (the
//! answers of the layers and extractors in front of the handlers) and with the
//! running server's limits. The default limits' document is committed as
//! `openapi/openapi.json` (a test fails when it is stale); a running server
//! serves its own at `/openapi.json` and `/docs`.

use axum::Json;
use axum::Router;
use axum::routing::get;
use serde_json::{Value, json};
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_scalar::{Scalar, Servable};

use super::routes::{OUTPUTS, api_routes, health_routes};
use super::{AppState, Limits};

/// The bearer token (when the server runs with one).
struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        if let Some(components) = openapi.components.as_mut() {
            components.add_security_scheme(
                "bearer",
                SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
            );
        }
    }
}

/// Everything but the paths, which come from the router.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "nuno model server",
        description = "Batched queries to neural-SDE dynamics with distance-aware uncertainty η (NUNO): \
            next-state samples, η, penalised rewards, truncation, policy actions, and MuJoCo-backed evaluation. \
            Every error is `{ \"error\": { \"code\", \"message\" } }` (KServe v2 routes: `{ \"error\": \"...\" }`). \
            With `--token`, every route except the health probes needs `Authorization: Bearer <token>`. \
            Row widths depend on the model (`obs_dim`, `act_dim` in `GET /v1/models/{id}`): a schema \
            cannot state them, and a row of another width is answered 422. The limits stated here are \
            the serving process's (`/openapi.json` on a running server).",
        license(name = "MIT OR Apache-2.0")
    ),
    components(schemas(crate::server::ErrorBody, crate::server::ErrorDetail, crate::server::V2ErrorBody)),
    modifiers(&BearerAuth),
    // The token is optional: a server started without `--token` needs none.
    security((), ("bearer" = [])),
    tags(
        (name = "models", description = "Model queries"),
        (name = "evaluation", description = "Runs in the real MuJoCo task"),
        (name = "kserve-v2", description = "KServe Open Inference Protocol v2"),
        (name = "admin", description = "Reloading models"),
        (name = "health", description = "Probes and metrics"),
    )
)]
struct ApiDoc;

/// The spec of a server running with `limits`.
pub fn document(limits: &Limits) -> Value {
    let spec = OpenApiRouter::<AppState>::with_openapi(ApiDoc::openapi())
        .merge(api_routes())
        .merge(health_routes())
        .into_openapi();
    let mut spec = serde_json::to_value(spec).expect("an OpenAPI document serialises");
    add_shared_answers(&mut spec);
    bound_numbers(&mut spec);
    nullable_answers(&mut spec);
    state_limits(&mut spec, limits);
    spec
}

/// The default limits' spec as pretty JSON, as committed in `openapi/openapi.json`.
pub fn openapi_json() -> String {
    serde_json::to_string_pretty(&document(&Limits::default())).expect("JSON serialises") + "\n"
}

/// Answers that come from in front of the handlers, added to every operation
/// that does not document them itself: the token check (401, where a token
/// may be needed), the body extractor (400, 413, 415, on routes with a body),
/// internal errors (500) and the request timeout or a cancelled computation
/// (503). KServe routes answer in the protocol's error shape.
fn add_shared_answers(spec: &mut Value) {
    let Some(paths) = spec["paths"].as_object_mut() else {
        return;
    };
    for (path, item) in paths.iter_mut() {
        let schema = if path.starts_with("/v2") {
            "#/components/schemas/V2ErrorBody"
        } else {
            "#/components/schemas/ErrorBody"
        };
        let Some(item) = item.as_object_mut() else {
            continue;
        };
        for operation in item.values_mut() {
            let open = operation["security"] == json!([{}]);
            let has_body = operation.get("requestBody").is_some();
            let shared = [
                (
                    "401",
                    !open,
                    "Missing or wrong bearer token (with `--token`)",
                ),
                (
                    "400",
                    has_body,
                    "Malformed body: not JSON / safetensors, or a field of the wrong type",
                ),
                (
                    "413",
                    has_body,
                    "Body larger than the server's `--max-body-bytes`",
                ),
                (
                    "415",
                    has_body,
                    "Content type other than the ones listed for the body",
                ),
                (
                    "500",
                    true,
                    "Internal error: the message carries an id the server's log explains",
                ),
                (
                    "503",
                    true,
                    "The request timed out (`--request-timeout-s`) or its computation was cancelled",
                ),
            ];
            let responses = &mut operation["responses"];
            for (status, applies, description) in shared {
                if applies && responses.get(status).is_none() {
                    responses[status] = json!({
                        "description": description,
                        "content": { "application/json": { "schema": { "$ref": schema } } }
                    });
                }
            }
        }
    }
}

/// f32::MAX as JSON writes it (its shortest decimal, a little above the exact
/// value): every number up to it reads as a finite f32.
const F32_BOUND: f64 = 3.402_823_5e38;

/// Numbers as the server reads them: an f32 must lie within ±f32::MAX (else
/// the body is malformed), and a u64 (utoipa writes `int64` with minimum 0)
/// goes up to u64::MAX, past what `int64` implies. Bounds a field states
/// itself are kept.
fn bound_numbers(value: &mut Value) {
    match value {
        Value::Object(map) => {
            match map.get("format").and_then(Value::as_str) {
                Some("float") => {
                    map.entry("minimum").or_insert(json!(-F32_BOUND));
                    map.entry("maximum").or_insert(json!(F32_BOUND));
                }
                Some("int64") if map.get("minimum") == Some(&json!(0)) => {
                    map.remove("format");
                    map.entry("maximum").or_insert(json!(u64::MAX));
                }
                _ => {}
            }
            map.values_mut().for_each(bound_numbers);
        }
        Value::Array(items) => items.iter_mut().for_each(bound_numbers),
        _ => {}
    }
}

/// JSON has no inf or NaN: an answer's number that overflowed f32 (a state
/// far off the data can send the drift there) is written as `null`, and the
/// answers' schemas say so. Binary answers carry the IEEE values.
fn nullable_answers(spec: &mut Value) {
    fn nullable(value: &mut Value) {
        match value {
            Value::Object(map) => {
                if map.get("type") == Some(&json!("number")) {
                    map.insert("type".into(), json!(["number", "null"]));
                }
                map.values_mut().for_each(nullable);
            }
            Value::Array(items) => items.iter_mut().for_each(nullable),
            _ => {}
        }
    }
    let schemas = &mut spec["components"]["schemas"];
    // Infer answers with the request's tensor schema: its copy allows null.
    let mut answered = schemas["InferTensor"].clone();
    answered["properties"]["data"] = json!({
        "type": "array",
        "items": { "type": ["number", "boolean", "null"] },
    });
    schemas["InferResponse"]["properties"]["outputs"]["items"] = answered;
    for answer in [
        "StepResponse",
        "Trajectory",
        "CandidateScore",
        "ActResponse",
        "ValidateResponse",
    ] {
        nullable(&mut schemas[answer]);
    }
}

/// This server's limits on request fields, as schema keywords.
fn state_limits(spec: &mut Value, limits: &Limits) {
    let schemas = &mut spec["components"]["schemas"];
    request_rules(schemas, limits);
    for (schema, property, keyword, limit) in stated_limits(limits) {
        let property = &mut schemas[schema]["properties"][property];
        debug_assert!(
            property.is_object(),
            "{schema}.{property} is not in the spec"
        );
        // Optional fields are `oneOf [null, T]`: the keyword goes on T.
        match property.get_mut("oneOf").and_then(Value::as_array_mut) {
            Some(variants) => {
                for variant in variants.iter_mut().filter(|v| v["type"] != "null") {
                    variant[keyword] = json!(limit);
                }
            }
            None => property[keyword] = json!(limit),
        }
    }
    kserve_constraints(schemas, limits);
}

/// (schema, property, keyword, limit) for each field a limit bounds.
fn stated_limits(limits: &Limits) -> Vec<(&'static str, &'static str, &'static str, usize)> {
    vec![
        ("StepRequest", "states", "maxItems", limits.max_batch),
        ("StepRequest", "actions", "maxItems", limits.max_batch),
        ("StepRequest", "particles", "maximum", limits.max_particles),
        ("RolloutRequest", "states", "maxItems", limits.max_batch),
        ("RolloutRequest", "actions", "maxItems", limits.max_batch),
        ("RolloutRequest", "horizon", "maximum", limits.max_horizon),
        (
            "RolloutRequest",
            "particles",
            "maximum",
            limits.max_particles,
        ),
        ("ScoreRequest", "states", "maxItems", limits.max_batch),
        ("ScoreRequest", "actions", "maxItems", limits.max_batch),
        (
            "ScoreRequest",
            "shared_actions",
            "maxItems",
            limits.max_batch,
        ),
        ("ScoreRequest", "horizon", "maximum", limits.max_horizon),
        ("ScoreRequest", "particles", "maximum", limits.max_particles),
        ("PlanRequest", "horizon", "maximum", limits.max_horizon),
        ("PlanRequest", "particles", "maximum", limits.max_particles),
        ("PlanRequest", "population", "maximum", limits.max_batch),
        (
            "PlanRequest",
            "iterations",
            "maximum",
            limits.max_plan_iterations,
        ),
        ("ActRequest", "states", "maxItems", limits.max_batch),
        ("ValidateRequest", "actions", "maxItems", limits.max_horizon),
        (
            "ValidateRequest",
            "particles",
            "maximum",
            limits.max_particles,
        ),
        (
            "EvaluateRequest",
            "episodes",
            "maximum",
            limits.max_episodes,
        ),
    ]
}

/// The rules between fields: one truncation rule at a time, one way to give
/// a score's candidates, and no start with more candidates than a batch has rows.
fn request_rules(schemas: &mut Value, limits: &Limits) {
    // Null is the same as absent.
    let one_rule = json!({
        "required": ["alpha", "threshold"],
        "properties": { "alpha": { "type": "number" }, "threshold": { "type": "number" } },
    });
    schemas["RolloutRequest"]["not"] = one_rule.clone();
    schemas["ScoreRequest"]["not"] = one_rule.clone();
    plan_request_rules(schemas, one_rule);
    let given =
        |field: &str| json!({ "required": [field], "properties": { field: { "type": "array" } } });
    schemas["ScoreRequest"]["oneOf"] = json!([given("actions"), given("shared_actions")]);
    // Array keywords hold only when the field is an array (null passes them).
    let score = &mut schemas["ScoreRequest"]["properties"];
    score["shared_actions"]["minItems"] = json!(1);
    let per_start = &mut score["actions"];
    per_start["minItems"] = json!(1);
    per_start["items"]["minItems"] = json!(1);
    per_start["items"]["maxItems"] = json!(limits.max_batch);
}

/// What a plan request may not combine: each planner's own settings with the
/// other's (null is absent), a session continued and one opened, α and a threshold.
fn plan_request_rules(schemas: &mut Value, one_rule: Value) {
    // Each planner's own settings, and none of the other's (null is absent).
    let set = |fields: &[&str]| {
        let one = |f: &&str| json!({ "required": [f], "properties": { *f: { "type": "number" } } });
        json!({ "anyOf": fields.iter().map(one).collect::<Vec<_>>() })
    };
    let planner_is = |name: &str| json!({ "properties": { "planner": { "const": name } } });
    let (mppi, cem, icem) = (
        ["temperature", "smoothing"],
        ["elites", "momentum"],
        ["decay", "colored_noise", "keep_elites"],
    );
    schemas["PlanRequest"]["allOf"] = json!([
        { "if": planner_is("cem"), "then": { "not": set(&[&mppi[..], &icem[..]].concat()) } },
        { "if": planner_is("icem"), "then": { "not": set(&mppi) } },
        { "if": planner_is("mppi"), "then": { "not": set(&[&cem[..], &icem[..]].concat()) } },
    ]);
    schemas["PlanRequest"]["not"] = json!({ "anyOf": [one_rule, {
        "required": ["session", "open_session"],
        "properties": { "session": { "type": "string" }, "open_session": { "const": true } },
    }] });
}

/// What KServe `infer` takes, as far as a schema can say it: exactly the
/// FP32 matrices `states` and `actions` (JSON `data`; the binary extension's
/// bodies are not described by a schema), known outputs and parameters.
fn kserve_constraints(schemas: &mut Value, limits: &Limits) {
    let named = |name: &str| {
        json!({ "contains": {
            "type": "object",
            "required": ["name", "datatype", "shape", "data"],
            "properties": {
                "name": { "const": name },
                "datatype": { "const": "FP32" },
                "shape": {
                    "minItems": 2,
                    "maxItems": 2,
                    "prefixItems": [
                        { "minimum": 1, "maximum": limits.max_batch },
                        { "minimum": 1 },
                    ],
                },
                "data": { "type": "array", "minItems": 1, "items": { "type": "number" } },
            },
        }})
    };
    let request = &mut schemas["InferRequest"]["properties"];
    let inputs = &mut request["inputs"];
    inputs["minItems"] = json!(2);
    inputs["maxItems"] = json!(2);
    inputs["allOf"] = json!([named("states"), named("actions")]);
    request["parameters"]["properties"] = json!({
        "seed": { "type": "integer", "minimum": 0 },
        "penalty": { "type": "number", "minimum": 0 },
        "noise_scale": { "type": "number", "minimum": 0 },
        "binary_data_output": { "type": "boolean" },
    });
    let output = &mut schemas["RequestedOutput"]["properties"];
    output["name"]["enum"] = json!(OUTPUTS);
    output["parameters"]["properties"] = json!({ "binary_data": { "type": "boolean" } });
}

pub(super) fn docs_routes(limits: &Limits) -> Router<AppState> {
    let spec = document(limits);
    Router::new()
        .route(
            "/openapi.json",
            get({
                let spec = spec.clone();
                || async move { Json(spec) }
            }),
        )
        .merge(Scalar::with_url("/docs", spec))
}
