"""The KubeRay manifests (``deploy/kuberay/raycluster.yaml``, ``rayjob.yaml``) against
``deploy/kuberay/schema.json``, a hand-written JSON schema of the RayCluster/RayJob CRD fields they
use (KubeRay v1.7.0): both validate, a misspelled or mistyped field does not, and the manifests
put laneshift's replay server and learner on the head's custom resources.

Room: tests, system (real Ray, zenoh or laneshift processes; the `system` marker). May import:
laneshift (any floor), pytest, numpy, the standard library and what the code under test needs."""

from __future__ import annotations

import copy
import json
import shlex
from pathlib import Path

import jsonschema
import pytest
import yaml

from laneshift.config import load_run_config

KUBERAY = Path(__file__).resolve().parents[1] / "deploy" / "kuberay"
SCHEMA = json.loads((KUBERAY / "schema.json").read_text())
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)
HEAD_RESOURCES = {"laneshift_replay": 1, "laneshift_learner": 1}


def manifest(name: str) -> dict:
    return yaml.safe_load((KUBERAY / name).read_text())


def cluster_spec(doc: dict) -> dict:
    return doc["spec"]["rayClusterSpec"] if doc["kind"] == "RayJob" else doc["spec"]


def errors(doc: dict) -> list[jsonschema.ValidationError]:
    return list(VALIDATOR.iter_errors(doc))


def ray_start_resources(params: dict[str, str]) -> dict:
    """``--resources`` as `ray start` gets it: KubeRay pastes ``--resources=<value>`` into the
    container's shell command line, so the value is shell-unquoted once, then JSON."""
    (word,) = shlex.split(f"--resources={params['resources']}")
    return json.loads(word.removeprefix("--resources="))


def test_schema_is_draft_2020_12_and_names_its_kuberay_version():
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
    assert SCHEMA["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert "KubeRay v1.7.0" in SCHEMA["$comment"]
    assert "59d663aeec13760646da3db9c1cf8cfe883e30b7" in SCHEMA["$comment"]


@pytest.mark.parametrize("name, kind", [("raycluster.yaml", "RayCluster"), ("rayjob.yaml", "RayJob")])
def test_manifest_validates(name, kind):
    doc = manifest(name)
    assert doc["apiVersion"] == "ray.io/v1" and doc["kind"] == kind
    assert errors(doc) == []


def _without_auth_options_with_env_secret(doc: dict) -> None:
    """KubeRay < 1.5.1's way (the manifests' comment): RAY_AUTH_MODE + RAY_AUTH_TOKEN from a Secret."""
    spec = cluster_spec(doc)
    del spec["authOptions"]
    env = [{"name": "RAY_AUTH_MODE", "value": "token"},
           {"name": "RAY_AUTH_TOKEN", "valueFrom": {"secretKeyRef": {"name": "laneshift-ray-token", "key": "auth_token"}}}]
    for group in [spec["headGroupSpec"], *spec["workerGroupSpecs"]]:
        group["template"]["spec"]["containers"][0]["env"] = copy.deepcopy(env)


def _with_pvc(doc: dict) -> None:
    """The run-dir volume as a PersistentVolumeClaim (the manifests' comment)."""
    (volume,) = cluster_spec(doc)["headGroupSpec"]["template"]["spec"]["volumes"]
    del volume["emptyDir"]
    volume["persistentVolumeClaim"] = {"claimName": "laneshift-runs"}


@pytest.mark.parametrize("name", ["raycluster.yaml", "rayjob.yaml"])
@pytest.mark.parametrize("variant", [_without_auth_options_with_env_secret, _with_pvc])
def test_the_commented_alternatives_validate(name, variant):
    doc = manifest(name)
    variant(doc)
    assert errors(doc) == []


def _head(doc):
    return cluster_spec(doc)["headGroupSpec"]


def _head_container(doc):
    return _head(doc)["template"]["spec"]["containers"][0]


def _env_group(doc):
    return cluster_spec(doc)["workerGroupSpecs"][0]


# (what is wrong, how to break a manifest, the schema keyword that must catch it)
BROKEN = [
    ("misspelled top-level spec field", lambda d: cluster_spec(d).__setitem__("workerGroupSpec", cluster_spec(d).pop("workerGroupSpecs")), "additionalProperties"),
    ("misspelled group field", lambda d: _env_group(d).__setitem__("rayStartParam", _env_group(d).pop("rayStartParams")), "additionalProperties"),
    ("misspelled container field", lambda d: _head_container(d).__setitem__("imagePullpolicy", _head_container(d).pop("imagePullPolicy")), "additionalProperties"),
    ("misspelled port field", lambda d: _head_container(d)["ports"][0].__setitem__("port", _head_container(d)["ports"][0].pop("containerPort")), "additionalProperties"),
    ("replicas as a string", lambda d: _env_group(d).__setitem__("replicas", "2"), "type"),
    ("rayStartParams value not a string", lambda d: _head(d)["rayStartParams"].__setitem__("num-cpus", 4), "type"),
    ("containerPort as a string", lambda d: _head_container(d)["ports"][0].__setitem__("containerPort", "6379"), "type"),
    ("authOptions.mode not in the enum", lambda d: cluster_spec(d)["authOptions"].__setitem__("mode", "tokens"), "enum"),
    ("imagePullPolicy not in the enum", lambda d: _head_container(d).__setitem__("imagePullPolicy", "Sometimes"), "enum"),
    ("a cpu limit that is no quantity", lambda d: _head_container(d)["resources"]["limits"].__setitem__("cpu", "4 cores"), "pattern"),
    ("worker group without groupName", lambda d: _env_group(d).pop("groupName"), "required"),
    ("worker group without maxReplicas", lambda d: _env_group(d).pop("maxReplicas"), "required"),
    ("head group without a template", lambda d: _head(d).pop("template"), "required"),
    ("a group without containers", lambda d: _head(d)["template"]["spec"].__setitem__("containers", []), "minItems"),
    ("negative minReplicas", lambda d: _env_group(d).__setitem__("minReplicas", -1), "minimum"),
    ("a name that is no DNS-1035 label", lambda d: d["metadata"].__setitem__("name", "Laneshift_Train"), "pattern"),
    ("another API version", lambda d: d.__setitem__("apiVersion", "ray.io/v1alpha2"), "const"),
]


@pytest.mark.parametrize("name", ["raycluster.yaml", "rayjob.yaml"])
@pytest.mark.parametrize("what, breaks, keyword", BROKEN, ids=[b[0] for b in BROKEN])
def test_broken_manifests_are_refused(name, what, breaks, keyword):
    doc = manifest(name)
    breaks(doc)
    found = errors(doc)
    assert found, f"{name}: {what} passed the schema"
    # Refused for that reason, not as a side effect of the edit.
    assert keyword in {e.validator for e in found}, [e.message for e in found]


@pytest.mark.parametrize("name", ["raycluster.yaml", "rayjob.yaml"])
def test_rayjob_fields_are_refused_on_a_raycluster_and_back(name):
    doc = manifest(name)
    if doc["kind"] == "RayCluster":
        doc["spec"]["entrypoint"] = "laneshift train"
    else:
        doc["spec"]["headGroupSpec"] = doc["spec"]["rayClusterSpec"]["headGroupSpec"]
    assert errors(doc)


def test_rayjob_spec_field_types():
    for field, value in [("shutdownAfterJobFinishes", "true"), ("ttlSecondsAfterFinished", -1),
                         ("submissionMode", "K8sJob"), ("entrypoint", ["laneshift", "train"])]:
        doc = manifest("rayjob.yaml")
        doc["spec"][field] = value
        assert errors(doc), field


@pytest.mark.parametrize("name", ["raycluster.yaml", "rayjob.yaml"])
def test_head_offers_replay_and_learner_resources_and_the_ports(name):
    doc = manifest(name)
    assert ray_start_resources(_head(doc)["rayStartParams"]) == HEAD_RESOURCES
    ports = {p["containerPort"]: p.get("name") for p in _head_container(doc)["ports"]}
    assert {6379, 8265, 10001, 7447} <= set(ports)
    assert ports[7447] == "zenoh"
    # Token auth through the operator (it creates the Secret and sets RAY_AUTH_MODE/RAY_AUTH_TOKEN);
    # KubeRay refuses token mode below Ray 2.52.0.
    spec = cluster_spec(doc)
    assert spec["authOptions"]["mode"] == "token"
    assert tuple(int(x) for x in spec["rayVersion"].split(".")) >= (2, 52, 0)
    # The custom resources are only on the head (and the optional GPU learner group).
    for group in spec["workerGroupSpecs"]:
        offered = ray_start_resources(group["rayStartParams"]) if "resources" in group["rayStartParams"] else {}
        assert "laneshift_replay" not in offered


def test_env_workers_and_the_optional_gpu_learner_group():
    groups = {g["groupName"]: g for g in manifest("raycluster.yaml")["spec"]["workerGroupSpecs"]}
    env = groups["env"]
    cpus = int(env["template"]["spec"]["containers"][0]["resources"]["limits"]["cpu"])
    assert ray_start_resources(env["rayStartParams"]) == {"laneshift_env": cpus}
    gpu = groups["gpu-learner"]
    assert gpu["replicas"] == 0  # optional: off until scaled up
    assert ray_start_resources(gpu["rayStartParams"]) == {"laneshift_learner": 1}
    assert gpu["template"]["spec"]["containers"][0]["resources"]["limits"]["nvidia.com/gpu"] == 1


def test_rayjob_entrypoint_places_replay_and_learner_on_the_head():
    doc = manifest("rayjob.yaml")
    argv = shlex.split(doc["spec"]["entrypoint"])  # the submitter's bash splits it the same way
    assert argv[:2] == ["laneshift", "train"]
    for flag, value in [("--cluster", "auto"), ("--workers", "8"), ("--scenario", "straight"),
                        ("--mode", "rehearsal"), ("--run-dir", "/data/runs/k8s")]:
        assert argv[argv.index(flag) + 1] == value, flag
    overrides = dict(argv[i + 1].split("=", 1) for i, a in enumerate(argv) if a == "--set")
    assert json.loads(overrides["deploy.replay_resources"]) == {"laneshift_replay": 1}
    assert json.loads(overrides["deploy.learner_resources"]) == {"laneshift_learner": 1}
    # laneshift's own config takes them, and what they ask for fits what the head offers.
    deploy = load_run_config(overrides=overrides).deploy
    offered = ray_start_resources(_head(doc)["rayStartParams"])
    for asked in (deploy.replay_resources, deploy.learner_resources):
        assert all(offered.get(k, 0) >= v for k, v in asked.items()), (asked, offered)
    # The run dir is on the head's volume.
    mounts = [m["mountPath"] for m in _head_container(doc)["volumeMounts"]]
    assert any(Path("/data/runs/k8s").is_relative_to(m) for m in mounts)
    assert doc["spec"]["shutdownAfterJobFinishes"] is True


def test_the_image_copies_every_folder_the_package_maps():
    """The Dockerfile copies the folders one by one (no .venv or runs/ from the build context), so a
    folder that pyproject.toml maps into ``laneshift`` and the image leaves out would build an image
    without that part of the package (``laneshift`` itself lives in tools/)."""
    import re
    import tomllib

    root = KUBERAY.parents[1]
    package_dir = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    tops = {path.split("/")[0] for path in package_dir.values()}
    copied = set(re.findall(r"^COPY (\S+) \./\1$", (KUBERAY / "Dockerfile").read_text(), re.M))
    assert {"src", "actors", "learner", "replay_server", "deploy", "tools"} <= tops
    assert tops <= copied, f"mapped but not copied into the image: {sorted(tops - copied)}"
