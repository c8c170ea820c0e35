"""Validates deploy/ offline: every Kubernetes object against the Kubernetes
schemas (kubernetes-validate, strict: unknown fields are errors), the KServe
objects' pod parts the same way (their CRD schemas are not bundled) plus the
fields KServe needs, the cross-references between objects, and every flag the
containers pass against `nuno-server --help`.

Usage: k8s_validate.py DEPLOY_DIR NUNO_SERVER_BINARY
"""

import pathlib
import re
import subprocess
import sys

import kubernetes_validate
import yaml

VERSION = "1.33.0"


def fail(message):
    sys.exit(f"deploy check: {message}")


def validate(obj, where):
    try:
        kubernetes_validate.validate(obj, VERSION, strict=True)
    except kubernetes_validate.ValidationError as e:
        fail(f"{where}: {e.message} at {'/'.join(str(p) for p in e.path)}")


def as_pod(containers, where):
    """Containers checked as a Pod's, the schema KServe embeds."""
    validate(
        {"apiVersion": "v1", "kind": "Pod", "metadata": {"name": "check"},
         "spec": {"containers": containers}},
        where,
    )


def check_flags(containers, help_text, where):
    for c in containers:
        for arg in c.get("args", []):
            flag = arg.split("=", 1)[0]
            if flag.startswith("--") and not re.search(rf"{re.escape(flag)}\b", help_text):
                fail(f"{where}: container {c['name']} passes {flag}, which nuno-server does not take")


def main():
    deploy, server = pathlib.Path(sys.argv[1]), sys.argv[2]
    help_text = subprocess.run([server, "--help"], capture_output=True, text=True, check=True).stdout
    objects = {}
    for path in sorted(deploy.rglob("*.yaml")):
        for doc in yaml.safe_load_all(path.read_text()):
            if doc:
                objects[(doc["kind"], doc["metadata"]["name"])] = (doc, path.name)
    kinds = {kind for kind, _ in objects}
    needed = {"Deployment", "Service", "HorizontalPodAutoscaler", "PersistentVolumeClaim",
              "ServingRuntime", "InferenceService"}
    if not needed <= kinds:
        fail(f"missing kinds: {sorted(needed - kinds)}")

    for (kind, name), (doc, file) in objects.items():
        where = f"{file}: {kind}/{name}"
        if doc["apiVersion"].startswith("serving.kserve.io/"):
            continue
        validate(doc, where)

    deployment = next(d for (k, _), (d, _) in objects.items() if k == "Deployment")
    pod = deployment["spec"]["template"]
    labels = pod["metadata"]["labels"]
    if deployment["spec"]["selector"]["matchLabels"] != labels:
        fail("the Deployment's selector does not match its pod labels")
    container = pod["spec"]["containers"][0]
    probes = (container["readinessProbe"]["httpGet"]["path"], container["livenessProbe"]["httpGet"]["path"])
    if probes != ("/readyz", "/healthz"):
        fail(f"probes are {probes}, expected /readyz and /healthz")
    check_flags(pod["spec"]["containers"], help_text, "Deployment")
    for (kind, name), (doc, _) in objects.items():
        if kind == "Service" and doc["spec"]["selector"] != labels:
            fail(f"Service/{name} selects {doc['spec']['selector']}, the pods carry {labels}")
        if kind == "HorizontalPodAutoscaler":
            target = doc["spec"]["scaleTargetRef"]
            if (target["kind"], target["name"]) != ("Deployment", deployment["metadata"]["name"]):
                fail(f"HorizontalPodAutoscaler/{name} scales {target}")
    for volume in pod["spec"]["volumes"]:
        claim = volume.get("persistentVolumeClaim", {}).get("claimName")
        if claim and ("PersistentVolumeClaim", claim) not in objects:
            fail(f"the Deployment mounts claim {claim}, which deploy/ does not define")

    runtimes = {n: d for (k, n), (d, _) in objects.items() if k == "ServingRuntime"}
    for name, runtime in runtimes.items():
        if runtime["apiVersion"] != "serving.kserve.io/v1alpha1":
            fail(f"ServingRuntime/{name}: apiVersion {runtime['apiVersion']}")
        spec = runtime["spec"]
        if "v2" not in spec.get("protocolVersions", []):
            fail(f"ServingRuntime/{name} does not declare protocol v2")
        if not spec.get("supportedModelFormats"):
            fail(f"ServingRuntime/{name} lists no model formats")
        as_pod(spec["containers"], f"ServingRuntime/{name} containers")
        check_flags(spec["containers"], help_text, f"ServingRuntime/{name}")
    for (kind, name), (doc, _) in objects.items():
        if kind != "InferenceService":
            continue
        if doc["apiVersion"] != "serving.kserve.io/v1beta1":
            fail(f"InferenceService/{name}: apiVersion {doc['apiVersion']}")
        model = doc["spec"]["predictor"]["model"]
        runtime = runtimes.get(model.get("runtime"))
        if runtime is None:
            fail(f"InferenceService/{name} names runtime {model.get('runtime')}, not defined in deploy/")
        formats = {f["name"] for f in runtime["spec"]["supportedModelFormats"]}
        if model["modelFormat"]["name"] not in formats:
            fail(f"InferenceService/{name}: format {model['modelFormat']['name']} not in {formats}")
        if model.get("protocolVersion") != "v2" or not model.get("storageUri"):
            fail(f"InferenceService/{name} needs protocolVersion v2 and a storageUri")
        as_pod([{"name": "check", "image": "check", "resources": model["resources"]}],
               f"InferenceService/{name} resources")
    print(f"deploy check: {len(objects)} objects valid")


if __name__ == "__main__":
    main()
