#!/usr/bin/env python3
"""Offline check of deploy/: renders the kustomizations as kustomize does and checks them.

No kubectl, kustomize or cluster: the kustomizations use a small subset of kustomize (resources,
components, namespace, labels, images, `$patch: delete` patches), which this script renders
itself and refuses anything else, so a kustomization it cannot render faithfully fails here
rather than being checked wrongly. `--compare-kubectl` compares the rendering with
`kubectl kustomize` where kubectl exists (not needed in CI).

Checked, for deploy/k8s (the base: built-in kinds only, so it applies to an empty cluster in one
go) and deploy/k8s-operators (the base + KEDA + Prometheus operator objects):
  - ordering: the Namespace is the first object and every namespaced object is in it; a
    ConfigMap or Secret comes before the objects that read it;
  - references: envFrom/env/volume ConfigMaps and Secrets (and their keys), Service selectors
    and target ports, HPA/PDB/NetworkPolicy/ServiceMonitor/ScaledObject selectors and targets,
    ServiceMonitor port names on the Service, TriggerAuthentication secrets, probe and scrape
    paths served by the process the pod runs;
  - images: every image is pantowatch:<Cargo.toml's version>, the kustomization's newTag too,
    never :latest; the migration Job is named after that version;
  - grace periods: API ≥ preStop + http.request_timeout_secs, worker ≥ worker.fit_budget_secs +
    worker.shutdown_grace_ms, read from the ConfigMap; every PANTOWATCH__* key is a setting of
    services/src/config.rs;
  - network policy: default deny, and the ports each component needs (API ↔ clients and DB,
    workers ↔ DB and webhook receivers, DNS);
  - autoscaling: at most one autoscaler per Deployment; the overlay scales workers on the queue;
  - CRD kinds (ServiceMonitor, PrometheusRule, ScaledObject, TriggerAuthentication), which
    kubernetes-validate has no schema for, against the fields their CRDs define;
  - monitoring: alert rules and dashboard parse (PromQL via promql_parser), name only metrics
    and labels the Rust code exports; the PrometheusRule carries exactly the alert rules;
  - compose healthchecks, Prometheus wiring and image tag; the Dockerfile's version labels.

Usage: check_kustomize.py [--deploy DIR] [--repo DIR] [--out DIR] [--compare-kubectl]
       check_kustomize.py --write-prometheusrule
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import re
import subprocess
import sys
from pathlib import Path

try:
    import yaml
except ImportError:  # PyYAML comes with kubernetes-validate (deploy/validate.sh installs it)
    sys.exit("check_kustomize.py: PyYAML is missing (pip install kubernetes-validate pulls it in)")
try:
    import promql_parser
except ImportError:
    sys.exit("check_kustomize.py: promql_parser is missing (pip install promql-parser)")
try:
    import jsonschema
except ImportError:
    sys.exit("check_kustomize.py: jsonschema is missing (pip install kubernetes-validate pulls it in)")

BASE = "k8s"
OVERLAYS = ["k8s-operators"]
NAMESPACE = "pantowatch"
IMAGE = "pantowatch"
PROMETHEUSRULE = "k8s/components/prometheus-operator/prometheusrule.yaml"
ALERTS = "prometheus/alerts.yml"
DASHBOARD = "grafana/pantowatch-dashboard.json"

errors: list[str] = []
DEPLOY = Path(__file__).resolve().parent  # --deploy


def fail(msg: str) -> None:
    errors.append(msg)


class RenderError(Exception):
    pass


# ---- a small kustomize ---------------------------------------------------------------------------

KUSTOMIZATION_FIELDS = {"apiVersion", "kind", "namespace", "labels", "images", "resources",
                        "components", "patches"}
CLUSTER_SCOPED = {"Namespace", "ClusterRole", "ClusterRoleBinding", "CustomResourceDefinition",
                  "PriorityClass", "StorageClass", "PersistentVolume", "IngressClass",
                  "RuntimeClass", "MutatingWebhookConfiguration", "ValidatingWebhookConfiguration",
                  "APIService", "ClusterTriggerAuthentication"}
TEMPLATE_PATH = {"Deployment": ["spec", "template"], "StatefulSet": ["spec", "template"],
                 "DaemonSet": ["spec", "template"], "ReplicaSet": ["spec", "template"],
                 "Job": ["spec", "template"], "CronJob": ["spec", "jobTemplate", "spec", "template"]}
# kustomize's default ("legacy") output order.
LEGACY_FIRST = ["Namespace", "ResourceQuota", "StorageClass", "CustomResourceDefinition",
                "ServiceAccount", "PodSecurityPolicy", "Role", "ClusterRole", "RoleBinding",
                "ClusterRoleBinding", "ConfigMap", "Secret", "Endpoints", "Service", "LimitRange",
                "PriorityClass", "PersistentVolume", "PersistentVolumeClaim", "Deployment",
                "StatefulSet", "CronJob", "PodDisruptionBudget"]
LEGACY_LAST = ["MutatingWebhookConfiguration", "ValidatingWebhookConfiguration"]


def group_of(api_version: str) -> str:
    return api_version.split("/")[0] if "/" in api_version else ""


def is_builtin(api_version: str) -> bool:
    """Kinds a cluster serves without any CRD: the core group, dot-less groups (apps, batch,
    policy, autoscaling) and *.k8s.io."""
    g = group_of(api_version)
    return g == "" or "." not in g or g.endswith(".k8s.io")


def ident(o: dict) -> str:
    md = o.get("metadata") or {}
    ns = md.get("namespace")
    return f"{o.get('kind')}/{(ns + '/') if ns else ''}{md.get('name')}"


def load_docs(path: Path) -> list[dict]:
    try:
        docs = [d for d in yaml.safe_load_all(path.read_text()) if d is not None]
    except yaml.YAMLError as e:
        raise RenderError(f"{path}: not YAML: {e}")
    for d in docs:
        if not isinstance(d, dict) or not d.get("kind") or not d.get("apiVersion") \
                or not (d.get("metadata") or {}).get("name"):
            raise RenderError(f"{path}: a document without apiVersion, kind or metadata.name")
        d.setdefault("metadata", {})
        d["_source"] = str(path)
        # As written, before the kustomization's images: (a manifest applied with -f runs these).
        d["_raw_images"] = {c.get("name"): c.get("image", "") for c in containers(d)}
    return docs


def kustomization_file(d: Path) -> Path:
    for n in ("kustomization.yaml", "kustomization.yml", "Kustomization"):
        if (d / n).is_file():
            return d / n
    raise RenderError(f"{d}: no kustomization.yaml")


def containers(o: dict) -> list[dict]:
    spec = pod_spec(o)
    if spec is None:
        return []
    return list(spec.get("initContainers") or []) + list(spec.get("containers") or [])


def template(o: dict) -> dict | None:
    path = TEMPLATE_PATH.get(o.get("kind"))
    if not path:
        return None
    t = o
    for p in path:
        t = (t or {}).get(p)
    return t


def pod_spec(o: dict) -> dict | None:
    t = template(o)
    return (t or {}).get("spec") if t else None


def pod_labels(o: dict) -> dict:
    t = template(o)
    return ((t or {}).get("metadata") or {}).get("labels") or {}


def split_image(image: str) -> tuple[str, str | None, str | None]:
    digest = None
    if "@" in image:
        image, digest = image.split("@", 1)
    name, tag = image, None
    last = image.rsplit("/", 1)[-1]
    if ":" in last:
        name, tag = image.rsplit(":", 1)
    return name, tag, digest


def build(d: Path, expect_kind: str, objs: list[dict] | None = None,
          trail: tuple = ()) -> tuple[list[dict], dict]:
    """Renders the kustomization (or, with `objs`, the component) in directory `d`.
    Returns the objects in kustomize's accumulation order and the kustomization itself."""
    d = d.resolve()
    if d in trail:
        raise RenderError(f"{d}: kustomization cycle")
    kf = kustomization_file(d)
    k = yaml.safe_load(kf.read_text()) or {}
    kind = k.get("kind", "Kustomization")
    if kind != expect_kind:
        raise RenderError(f"{kf}: kind {kind}, expected {expect_kind}")
    unknown = set(k) - KUSTOMIZATION_FIELDS
    if unknown:
        raise RenderError(f"{kf}: fields {sorted(unknown)} are not rendered by check_kustomize.py "
                          "(extend it, or the check would not see what kustomize does)")
    out = list(objs or [])
    for r in k.get("resources") or []:
        p = (d / r).resolve()
        if p.is_dir():
            for anc in [d, *trail]:
                if p in Path(anc).parents or p == anc:
                    raise RenderError(f"{kf}: resource {r} contains this kustomization "
                                      "(kustomize refuses an overlay inside its base)")
            sub, _ = build(p, "Kustomization", None, trail + (d,))
            out += sub
        elif p.is_file():
            out += load_docs(p)
        else:
            raise RenderError(f"{kf}: resource {r} does not exist")
    for c in k.get("components") or []:
        out, _ = build((d / c).resolve(), "Component", out, trail + (d,))
    seen = {}
    for o in out:
        key = (o["kind"], group_of(o["apiVersion"]), o["metadata"].get("namespace"),
               o["metadata"]["name"])
        if key in seen:
            raise RenderError(f"{kf}: {ident(o)} defined twice ({seen[key]}, {o['_source']})")
        seen[key] = o["_source"]
    for p in k.get("patches") or []:
        out = apply_patch(kf, d, p, out)
    ns = k.get("namespace")
    if ns:
        for o in out:
            if o["kind"] not in CLUSTER_SCOPED:
                o["metadata"]["namespace"] = ns
    for entry in k.get("labels") or []:
        extra = set(entry) - {"pairs", "includeSelectors", "includeTemplates"}
        if extra or entry.get("includeSelectors"):
            raise RenderError(f"{kf}: labels with {sorted(extra) or 'includeSelectors'} are not "
                              "rendered by check_kustomize.py")
        for o in out:
            o["metadata"].setdefault("labels", {}).update(entry.get("pairs") or {})
            t = template(o) if entry.get("includeTemplates") else None
            if t is not None:
                t.setdefault("metadata", {}).setdefault("labels", {}).update(entry["pairs"])
    for img in k.get("images") or []:
        extra = set(img) - {"name", "newName", "newTag", "digest"}
        if extra:
            raise RenderError(f"{kf}: images fields {sorted(extra)} not rendered")
        for o in out:
            for c in containers(o):
                name, tag, digest = split_image(c.get("image", ""))
                if name != img["name"]:
                    continue
                name = img.get("newName", name)
                tag = img.get("newTag", tag)
                if img.get("digest"):
                    digest, tag = img["digest"], None
                c["image"] = name + (f":{tag}" if tag else "") + (f"@{digest}" if digest else "")
    return out, k


def apply_patch(kf: Path, d: Path, p: dict, objs: list[dict]) -> list[dict]:
    if set(p) - {"patch", "path"}:
        raise RenderError(f"{kf}: patches with {sorted(set(p) - {'patch', 'path'})} not rendered")
    text = p["patch"] if "patch" in p else (d / p["path"]).read_text()
    doc = yaml.safe_load(text)
    if not isinstance(doc, dict) or doc.get("$patch") != "delete":
        raise RenderError(f"{kf}: only `$patch: delete` patches are rendered by check_kustomize.py")
    md = doc.get("metadata") or {}
    keep, hit = [], 0
    for o in objs:
        if (o["kind"] == doc.get("kind") and group_of(o["apiVersion"]) == group_of(doc.get("apiVersion", ""))
                and o["metadata"]["name"] == md.get("name")
                and md.get("namespace") in (None, o["metadata"].get("namespace"))):
            hit += 1
            continue
        keep.append(o)
    if hit != 1:
        raise RenderError(f"{kf}: the delete patch of {doc.get('kind')}/{md.get('name')} matches "
                          f"{hit} objects (kustomize needs exactly one)")
    return keep


def legacy_sorted(objs: list[dict]) -> list[dict]:
    def key(o):
        k = o["kind"]
        rank = (LEGACY_FIRST.index(k) if k in LEGACY_FIRST else
                len(LEGACY_FIRST) + 1 + LEGACY_LAST.index(k) if k in LEGACY_LAST else
                len(LEGACY_FIRST))
        g = group_of(o["apiVersion"]) or "~G"
        v = o["apiVersion"].split("/")[-1]
        return (rank, f"{g}_{v}_{k}", o["metadata"].get("namespace") or "", o["metadata"]["name"])
    return sorted(objs, key=key)


def clean(o: dict) -> dict:
    return {k: v for k, v in o.items() if not k.startswith("_")}


# ---- facts from the code -------------------------------------------------------------------------

class Code:
    """What the Rust sources export and accept."""

    def __init__(self, repo: Path):
        self.repo = repo
        src = repo / "services" / "src"
        if not src.is_dir():
            raise SystemExit(f"check_kustomize.py: {src} not found (--repo)")
        self.sources = {p: p.read_text() for p in sorted(src.rglob("*.rs"))}
        self.metrics = self._metrics()
        self.settings = self._settings((src / "config.rs").read_text())
        self.api_paths = set(json.loads((repo / "services" / "openapi.json").read_text())["paths"])
        self.worker_paths = self._worker_paths((src / "server.rs").read_text())
        self.job_states = self._job_states()
        t = repo / "Cargo.toml"
        m = re.search(r'^\[workspace\.package\][^\[]*?^version\s*=\s*"([^"]+)"', t.read_text(), re.M | re.S)
        if not m:
            raise SystemExit("check_kustomize.py: no [workspace.package] version in Cargo.toml")
        self.version = m.group(1)

    def _metrics(self) -> dict[str, dict]:
        """series name → {"labels": {label: set of literal values or None}} for every series the
        code exports (histograms as _bucket/_sum/_count when buckets are configured for them)."""
        macros: dict[str, dict] = {}
        kinds: dict[str, str] = {}
        for path, text in self.sources.items():
            for m in re.finditer(r'metrics::(counter|gauge|histogram)!\(\s*"([a-zA-Z_:][a-zA-Z0-9_:]*)"', text):
                kind, name = m.group(1), m.group(2)
                depth, i = 0, m.end() - len(m.group(0)) + m.group(0).index("(")
                for j in range(i, len(text)):
                    depth += {"(": 1, ")": -1}.get(text[j], 0)
                    if depth == 0:
                        break
                args = text[m.end():j]
                kinds[name] = kind
                labels = macros.setdefault(name, {})
                for lm in re.finditer(r'"([a-zA-Z_][a-zA-Z0-9_]*)"\s*=>\s*("([^"]*)"|[^,)]+)', args):
                    label, lit = lm.group(1), lm.group(3)
                    if lit is not None:
                        values = {lit}
                    else:
                        var = lm.group(2).strip()
                        values = self._loop_literals(text[:m.start()], var)
                        if values is None:
                            values = self._param_literals(text, m.start(), var)
                    if label in labels and (labels[label] is None or values is None):
                        labels[label] = None
                    else:
                        labels[label] = (labels.get(label) or set()) | values if values is not None else None
        tele = "".join(self.sources.values())
        bucket_suffixes = re.findall(r'Matcher::Suffix\("([^"]+)"', tele)
        bucket_full = re.findall(r'Matcher::Full\("([^"]+)"', tele)
        series = {}
        for name, labels in macros.items():
            if kinds[name] == "histogram":
                if any(name.endswith(s) for s in bucket_suffixes) or name in bucket_full:
                    series[name + "_bucket"] = {**labels, "le": None}
                else:
                    series[name] = {**labels, "quantile": None}
                series[name + "_sum"] = dict(labels)
                series[name + "_count"] = dict(labels)
            else:
                series[name] = labels
        return series

    @staticmethod
    def _loop_literals(before: str, var: str) -> set | None:
        """The values of a label given as a variable bound by `for (var, _) in [("a", ..), ...]`
        shortly before the macro (ops.rs: pantowatch_jobs{state})."""
        if not re.fullmatch(r"[a-z_][a-z0-9_]*", var):
            return None
        m = None
        for m in re.finditer(r"for\s*\(\s*" + var + r"\s*,[^)]*\)\s*in\s*\[(?P<body>[^\]]*)\]", before[-1500:]):
            pass
        return set(re.findall(r'\(\s*"([^"]*)"', m.group("body"))) if m else None

    def _param_literals(self, text: str, pos: int, var: str) -> set | None:
        """The values of a label given as a parameter of the enclosing function: the literals
        its callers pass (or that a `fn name(&self) -> &'static str` they call returns)."""
        fns = list(re.finditer(r"\bfn\s+(\w+)\s*(?:<[^>]*>)?\(", text[:pos]))
        if not fns or not re.fullmatch(r"[a-z_][a-z0-9_]*", var):
            return None
        name = fns[-1].group(1)
        params = [a.split(":")[0].strip() for a in split_args(text, fns[-1].end())]
        if var not in params:
            return None
        idx, values = params.index(var), set()
        for src in self.sources.values():
            for call in re.finditer(r"(?<![\w:])" + name + r"\(", src):
                if re.search(r"\bfn\s+$", src[:call.start()]):
                    continue
                args = split_args(src, call.end())
                if len(args) <= idx:
                    return None
                a = args[idx].strip()
                lit = re.fullmatch(r'"([^"]*)"', a)
                meth = re.fullmatch(r"[\w.]+\.(\w+)\(\)", a)
                if lit:
                    values.add(lit.group(1))
                elif meth:
                    returned = self._returned_literals(meth.group(1))
                    if not returned:
                        return None
                    values |= returned
                else:
                    return None
        return values or None

    def _returned_literals(self, method: str) -> set[str]:
        out = set()
        for src in self.sources.values():
            for f in re.finditer(r"\bfn\s+" + method + r"\s*\(&self\)\s*->\s*&'static str\s*\{", src):
                depth, j = 1, f.end()
                while depth and j < len(src):
                    depth += {"{": 1, "}": -1}.get(src[j], 0)
                    j += 1
                out |= set(re.findall(r'=>\s*"([^"]*)"', src[f.end():j]))
        return out

    @staticmethod
    def _settings(text: str) -> set[str]:
        """Every PANTOWATCH__* variable config.rs accepts."""
        def fields(struct: str) -> list[tuple[str, str]]:
            m = re.search(r"pub struct " + struct + r"\s*\{(.*?)\n\}", text, re.S)
            if not m:
                raise SystemExit(f"check_kustomize.py: struct {struct} not found in config.rs")
            return re.findall(r"^\s*pub (\w+): ([\w:<>]+)", m.group(1), re.M)
        keys = set()
        for name, ty in fields("Settings"):
            if ty.endswith("Settings"):
                keys |= {f"PANTOWATCH__{name.upper()}__{f.upper()}" for f, _ in fields(ty)}
            else:
                keys.add(f"PANTOWATCH__{name.upper()}")
        return keys

    @staticmethod
    def _worker_paths(text: str) -> set[str]:
        m = re.search(r"pub fn worker_metrics_router.*?\n\}", text, re.S)
        return set(re.findall(r'\.route\(\s*"([^"]+)"', m.group(0))) if m else set()

    def _job_states(self) -> set[str]:
        sql = "".join(p.read_text() for p in sorted((self.repo / "migrations" / "postgres").glob("*.sql")))
        m = re.search(r"CREATE TABLE jobs.*?state\s+TEXT[^,]*?CHECK \(state IN \(([^)]*)\)\)", sql, re.S)
        return set(re.findall(r"'([a-z_]+)'", m.group(1))) if m else set()


def split_args(text: str, start: int) -> list[str]:
    """The top-level comma-separated arguments from `start` (just after an opening parenthesis)
    to its closing one."""
    args, depth, cur, i, in_str = [], 0, "", start, False
    while i < len(text):
        ch = text[i]
        if in_str:
            if ch == "\\":
                cur += text[i:i + 2]
                i += 2
                continue
            in_str = ch != '"'
        elif ch == '"':
            in_str = True
        elif ch in "([{<" and not (ch == "<" and text[i - 1] == " "):
            depth += 1
        elif ch in ")]}>" and not (ch == ">" and text[i - 1] in "=-"):
            if depth == 0:
                break
            depth -= 1
        elif ch == "," and depth == 0:
            args.append(cur)
            cur = ""
            i += 1
            continue
        cur += ch
        i += 1
    if cur.strip():
        args.append(cur)
    return args


# ---- selectors and lookups -----------------------------------------------------------------------

def selector_matches(sel: dict | None, labels: dict, plain: bool = False) -> bool:
    if sel is None:
        return False
    if plain:
        return bool(sel) and all(labels.get(k) == v for k, v in sel.items())
    ml = sel.get("matchLabels") or {}
    if any(labels.get(k) != v for k, v in ml.items()):
        return False
    for e in sel.get("matchExpressions") or []:
        k, op, vals = e["key"], e["operator"], e.get("values") or []
        if op == "In" and labels.get(k) not in vals:
            return False
        if op == "NotIn" and labels.get(k) in vals:
            return False
        if op == "Exists" and k not in labels:
            return False
        if op == "DoesNotExist" and k in labels:
            return False
    return True


def empty_selector(sel: dict | None) -> bool:
    return sel is not None and not sel.get("matchLabels") and not sel.get("matchExpressions")


class Rendered:
    def __init__(self, name: str, objs: list[dict], k: dict):
        self.name, self.objs, self.k = name, objs, k

    def find(self, kind: str, ns: str | None, name: str) -> dict | None:
        for o in self.objs:
            if o["kind"] == kind and o["metadata"]["name"] == name and \
                    (kind in CLUSTER_SCOPED or o["metadata"].get("namespace") == ns):
                return o
        return None

    def of(self, *kinds: str) -> list[dict]:
        return [o for o in self.objs if o["kind"] in kinds]

    def workloads(self) -> list[dict]:
        return [o for o in self.objs if o["kind"] in TEMPLATE_PATH]

    def pods_selected(self, ns: str, sel: dict, plain: bool = False, kinds=None) -> list[dict]:
        return [w for w in self.workloads() if w["metadata"].get("namespace") == ns
                and (kinds is None or w["kind"] in kinds)
                and selector_matches(sel, pod_labels(w), plain)]


def env_of(r: Rendered, w: dict, c: dict) -> dict[str, str]:
    """The container's environment as far as the manifests define it (envFrom, then env)."""
    ns = w["metadata"].get("namespace")
    env: dict[str, str] = {}
    for ef in c.get("envFrom") or []:
        for kind, key in (("ConfigMap", "configMapRef"), ("Secret", "secretRef")):
            if key in ef:
                o = r.find(kind, ns, ef[key]["name"])
                if o:
                    env.update({k: str(v) for k, v in (o.get("data") or {}).items()})
                    env.update({k: str(v) for k, v in (o.get("stringData") or {}).items()})
    for e in c.get("env") or []:
        if "value" in e:
            env[e["name"]] = str(e["value"])
    return env


def command_of(c: dict) -> str:
    args = list(c.get("command") or []) + list(c.get("args") or [])
    return next((a for a in args if a in ("serve", "worker", "migrate")), "")


def port_of(addr: str) -> int | None:
    m = re.search(r":(\d+)$", addr or "")
    return int(m.group(1)) if m else None


# ---- checks on one rendering ----------------------------------------------------------------------

def check_rendering(r: Rendered, code: Code, base: bool) -> None:
    where = f"{r.name}:"
    objs = r.objs
    # Ordering and namespace.
    if not objs or objs[0]["kind"] != "Namespace":
        fail(f"{where} the first object is {ident(objs[0]) if objs else 'none'}, not the Namespace "
             "(list namespace.yaml first)")
    if r.k.get("namespace") != NAMESPACE:
        fail(f"{where} kustomization namespace is {r.k.get('namespace')!r}, not {NAMESPACE!r}")
    created_at = {o["metadata"]["name"]: i for i, o in enumerate(objs) if o["kind"] == "Namespace"}
    for i, o in enumerate(objs):
        if o["kind"] in CLUSTER_SCOPED:
            continue
        ns = o["metadata"].get("namespace")
        if ns != NAMESPACE:
            fail(f"{where} {ident(o)} is not in namespace {NAMESPACE}")
        if ns not in created_at:
            fail(f"{where} {ident(o)}: its namespace {ns} is not created by this kustomization")
        elif created_at[ns] > i:
            fail(f"{where} {ident(o)} comes before its Namespace")
    if base:
        for o in objs:
            if not is_builtin(o["apiVersion"]):
                fail(f"{where} {ident(o)} ({o['apiVersion']}) needs a CRD: the base must apply to an "
                     "empty cluster (put it in a component used by deploy/k8s-operators)")
    position = {id(o): i for i, o in enumerate(objs)}

    def ref(owner: dict, kind: str, name: str, key: str | None = None, what: str = "") -> dict | None:
        ns = owner["metadata"].get("namespace")
        o = r.find(kind, ns, name)
        if o is None:
            fail(f"{where} {ident(owner)}: {what or kind} {name!r} does not exist in {ns}")
            return None
        if key is not None and key not in (o.get("data") or {}) and key not in (o.get("stringData") or {}):
            fail(f"{where} {ident(owner)}: {kind} {name!r} has no key {key!r}")
        if kind in ("ConfigMap", "Secret") and position[id(o)] > position[id(owner)]:
            fail(f"{where} {ident(owner)} comes before the {kind} {name} it reads")
        return o

    # Images and the migration Job.
    slug = code.version.replace(".", "-").lower()
    tags = [i.get("newTag") for i in r.k.get("images") or [] if i.get("name") == IMAGE]
    if base and tags != [code.version]:
        fail(f"{where} kustomization images newTag for {IMAGE} is {tags}, not Cargo.toml's "
             f"version {code.version!r} (deploy/set-version.sh)")
    for w in r.workloads():
        for c in containers(w):
            for stage, image in (("rendered", c.get("image", "")),
                                 (f"in {Path(w['_source']).name}", w["_raw_images"].get(c["name"], ""))):
                name, tag, digest = split_image(image)
                if tag in (None, "latest") and not digest:
                    fail(f"{where} {ident(w)} container {c['name']}: image {image!r} ({stage}) is "
                         "untagged or :latest")
                elif name.rsplit("/", 1)[-1] == IMAGE and tag != code.version:
                    fail(f"{where} {ident(w)} container {c['name']}: image tag {tag!r} ({stage}) is not "
                         f"Cargo.toml's version {code.version!r} (deploy/set-version.sh)")
    migrate_jobs = [w for w in r.of("Job") if any(command_of(c) == "migrate" for c in containers(w))]
    if len(migrate_jobs) != 1:
        fail(f"{where} {len(migrate_jobs)} migration Jobs (want one, running `pantowatch migrate`)")
    for j in migrate_jobs:
        want = f"pantowatch-migrate-{slug}"
        if j["metadata"]["name"] != want:
            fail(f"{where} {ident(j)}: a migration Job per image tag must be named {want} "
                 "(its pod template is immutable; deploy/set-version.sh)")
        if "ttlSecondsAfterFinished" not in j["spec"]:
            fail(f"{where} {ident(j)}: no ttlSecondsAfterFinished")

    # References from pod templates.
    for w in r.workloads():
        spec = pod_spec(w) or {}
        for c in containers(w):
            for ef in c.get("envFrom") or []:
                for kind, key in (("ConfigMap", "configMapRef"), ("Secret", "secretRef")):
                    if key in ef and not ef[key].get("optional"):
                        ref(w, kind, ef[key]["name"], what=f"envFrom {key}")
            for e in c.get("env") or []:
                vf = e.get("valueFrom") or {}
                for kind, key in (("ConfigMap", "configMapKeyRef"), ("Secret", "secretKeyRef")):
                    if key in vf and not vf[key].get("optional"):
                        ref(w, kind, vf[key]["name"], vf[key]["key"], what=f"env {e['name']} {key}")
            ports = {p.get("name"): p["containerPort"] for p in c.get("ports") or []}
            for probe in ("livenessProbe", "readinessProbe", "startupProbe"):
                hg = (c.get(probe) or {}).get("httpGet")
                if not hg:
                    continue
                if isinstance(hg["port"], str) and hg["port"] not in ports:
                    fail(f"{where} {ident(w)} {probe}: port {hg['port']!r} is not a port of container {c['name']}")
                check_path_served(where, w, c, hg.get("path", "/"), code, probe)
        for v in spec.get("volumes") or []:
            if "configMap" in v and not v["configMap"].get("optional"):
                ref(w, "ConfigMap", v["configMap"]["name"], what=f"volume {v['name']}")
            if "secret" in v and not v["secret"].get("optional"):
                ref(w, "Secret", v["secret"]["secretName"], what=f"volume {v['name']}")
            if "persistentVolumeClaim" in v:
                ref(w, "PersistentVolumeClaim", v["persistentVolumeClaim"]["claimName"])
        sa = spec.get("serviceAccountName")
        if sa and sa != "default":
            ref(w, "ServiceAccount", sa)

    # Services.
    for s in r.of("Service"):
        ns = s["metadata"].get("namespace")
        sel = (s.get("spec") or {}).get("selector")
        pods = r.pods_selected(ns, sel or {}, plain=True)
        if not pods:
            fail(f"{where} {ident(s)}: selector {sel} matches no pod template")
            continue
        for p in s["spec"].get("ports") or []:
            tp = p.get("targetPort", p["port"])
            for w in pods:
                cps = [cp for c in containers(w) for cp in c.get("ports") or []]
                if not any(cp.get("name") == tp or cp["containerPort"] == tp for cp in cps):
                    fail(f"{where} {ident(s)} port {p.get('name')}: targetPort {tp!r} is no port of {ident(w)}")

    # Autoscalers: targets exist, one autoscaler per target.
    scalers: dict[tuple, list[str]] = {}
    for h in r.of("HorizontalPodAutoscaler", "ScaledObject"):
        t = h["spec"]["scaleTargetRef"]
        kind = t.get("kind", "Deployment")
        if ref(h, kind, t["name"], what=f"scaleTargetRef {kind}") is not None:
            scalers.setdefault((kind, t["name"]), []).append(ident(h))
    for target, by in scalers.items():
        if len(by) > 1:
            fail(f"{where} {target[0]}/{target[1]} has {len(by)} autoscalers ({', '.join(by)}): "
                 "KEDA's ScaledObject creates an HPA of its own; two fight over the replicas")
    for d in r.of("Deployment"):
        scaled = ("Deployment", d["metadata"]["name"]) in scalers
        if scaled and "replicas" in d["spec"]:
            fail(f"{where} {ident(d)} sets replicas although an autoscaler owns them "
                 "(each apply would reset the count)")

    # Disruption budgets: every long-running Deployment has one, every budget selects pods.
    for p in r.of("PodDisruptionBudget"):
        if not r.pods_selected(p["metadata"]["namespace"], p["spec"].get("selector"), kinds={"Deployment", "StatefulSet"}):
            fail(f"{where} {ident(p)}: selector matches no Deployment's pods")
    for d in r.of("Deployment"):
        if not any(selector_matches(p["spec"].get("selector"), pod_labels(d)) for p in r.of("PodDisruptionBudget")):
            fail(f"{where} {ident(d)} has no PodDisruptionBudget")

    check_network_policies(r, code, where)
    check_grace_periods(r, where)
    check_settings_and_ports(r, code, where)

    # CRD kinds.
    for o in objs:
        schema = CRD_SCHEMAS.get((o["apiVersion"], o["kind"]))
        if schema is not None:
            for e in sorted(jsonschema.Draft7Validator(schema).iter_errors(clean(o)), key=str):
                path = "/".join(str(p) for p in e.absolute_path)
                fail(f"{where} {ident(o)}: {path or '(top)'}: {e.message}")
        elif not is_builtin(o["apiVersion"]):
            fail(f"{where} {ident(o)}: no structural check for {o['apiVersion']} {o['kind']} (add one)")
    for sm in r.of("ServiceMonitor"):
        ns = sm["metadata"]["namespace"]
        nss = (sm["spec"].get("namespaceSelector") or {}).get("matchNames") or [ns]
        svcs = [s for s in r.of("Service") if s["metadata"]["namespace"] in nss
                and selector_matches(sm["spec"].get("selector"), s["metadata"].get("labels") or {})]
        if not svcs:
            fail(f"{where} {ident(sm)}: selector matches no Service")
        for ep in sm["spec"].get("endpoints") or []:
            for s in svcs:
                names = [p.get("name") for p in s["spec"].get("ports") or []]
                if ep.get("port") not in names:
                    fail(f"{where} {ident(sm)}: endpoint port {ep.get('port')!r} is not a port name of "
                         f"{ident(s)} ({names})")
                    continue
                for w in r.pods_selected(s["metadata"]["namespace"], s["spec"].get("selector") or {}, plain=True):
                    for c in containers(w):
                        check_path_served(where, w, c, ep.get("path", "/metrics"), code, f"{ident(sm)} scrape")
    for ta in r.of("TriggerAuthentication"):
        for st in ta["spec"].get("secretTargetRef") or []:
            ref(ta, "Secret", st["name"], st["key"], what="secretTargetRef")
    for so in r.of("ScaledObject"):
        spec = so["spec"]
        if spec.get("minReplicaCount", 0) > spec.get("maxReplicaCount", 100):
            fail(f"{where} {ident(so)}: minReplicaCount > maxReplicaCount")
        if "fallback" in spec and any(t.get("metricType", "AverageValue") != "AverageValue"
                                      for t in spec.get("triggers") or []):
            fail(f"{where} {ident(so)}: KEDA's fallback works with AverageValue triggers only")
        for t in spec.get("triggers") or []:
            a = t.get("authenticationRef")
            if a:
                ref(so, a.get("kind", "TriggerAuthentication"), a["name"], what="authenticationRef")
            md = t.get("metadata") or {}
            if t["type"] == "postgresql":
                q = md.get("query", "")
                if not re.search(r"\bFROM\s+jobs\b", q, re.I):
                    fail(f"{where} {ident(so)}: the postgresql trigger's query does not read the jobs table")
                for st in re.findall(r"'([a-z_]+)'", q):
                    if st not in code.job_states:
                        fail(f"{where} {ident(so)}: job state {st!r} is not one of {sorted(code.job_states)} "
                             "(migrations/postgres)")
                for key in ("targetQueryValue", "activationTargetQueryValue"):
                    if key in md and not re.fullmatch(r"\d+(\.\d+)?", md[key]):
                        fail(f"{where} {ident(so)}: {key} {md[key]!r} is not a number")
            elif t["type"] == "prometheus":
                check_promql(f"{where} {ident(so)} trigger", md.get("query", ""), code)
    if not base:
        workers = [d for d in r.of("Deployment") if any(command_of(c) == "worker" for c in containers(d))]
        for d in workers:
            by = [so for so in r.of("ScaledObject") if so["spec"]["scaleTargetRef"]["name"] == d["metadata"]["name"]
                  and any(t["type"] in ("postgresql", "prometheus") for t in so["spec"].get("triggers") or [])]
            if not by:
                fail(f"{where} {ident(d)} does not scale on the queue depth (no ScaledObject with a "
                     "postgresql or prometheus trigger)")
        for pr in r.of("PrometheusRule"):
            check_prometheusrule_equals_alerts(where, pr)


def check_path_served(where: str, w: dict, c: dict, path: str, code: Code, what: str) -> None:
    cmd = command_of(c)
    served = code.api_paths if cmd == "serve" else code.worker_paths if cmd == "worker" else None
    if served is None:
        fail(f"{where} {ident(w)} {what}: container {c['name']} runs no pantowatch server")
    elif path not in served:
        fail(f"{where} {ident(w)} {what}: `pantowatch {cmd}` serves no {path} "
             f"({'services/openapi.json' if cmd == 'serve' else 'server.rs worker_metrics_router'})")


def check_network_policies(r: Rendered, code: Code, where: str) -> None:
    nps = r.of("NetworkPolicy")
    if not any(empty_selector(n["spec"].get("podSelector")) and
               set(n["spec"].get("policyTypes") or []) == {"Ingress", "Egress"} and
               not n["spec"].get("ingress") and not n["spec"].get("egress") for n in nps):
        fail(f"{where} no default-deny NetworkPolicy (podSelector {{}}, Ingress and Egress, no rules)")
    for n in nps:
        sel = n["spec"].get("podSelector")
        if not empty_selector(sel) and not r.pods_selected(n["metadata"]["namespace"], sel):
            fail(f"{where} {ident(n)}: podSelector matches no pod template")

    def allowed(w: dict, direction: str) -> set:
        out = set()
        for n in nps:
            if n["metadata"]["namespace"] != w["metadata"]["namespace"]:
                continue
            if not selector_matches(n["spec"].get("podSelector"), pod_labels(w)):
                continue
            if direction.capitalize() not in (n["spec"].get("policyTypes") or ["Ingress"]):
                continue
            for rule in n["spec"].get(direction) or []:
                ports = rule.get("ports")
                if not ports:
                    out.add("*")
                for p in ports or []:
                    port = p.get("port", "*")
                    if isinstance(port, str) and port != "*":
                        named = [cp["containerPort"] for c in containers(w) for cp in c.get("ports") or []
                                 if cp.get("name") == port]
                        port = named[0] if named else port
                    out.add((p.get("protocol", "TCP"), port))
        return out

    db_url = ""
    for s in r.of("Secret"):
        db_url = (s.get("stringData") or {}).get("PANTOWATCH__DATABASE__URL", db_url)
    m = re.match(r"postgres(?:ql)?://[^/]*?:(\d+)/", db_url)
    db_port = int(m.group(1)) if m else 5432
    for w in r.workloads():
        roles = {command_of(c) for c in containers(w)} - {""}
        if not roles:
            continue
        eg, ing = allowed(w, "egress"), allowed(w, "ingress")
        needs_out = {("TCP", db_port): "PostgreSQL", ("UDP", 53): "DNS"}
        if roles & {"serve", "worker"}:
            needs_out[("TCP", 443)] = "webhook receivers (https)"
        for need, what in needs_out.items():
            if need not in eg and "*" not in eg:
                fail(f"{where} {ident(w)}: no NetworkPolicy allows egress {need[0]}/{need[1]} ({what})")
        for c in containers(w):
            for cp in c.get("ports") or []:
                if ("TCP", cp["containerPort"]) not in ing and "*" not in ing:
                    fail(f"{where} {ident(w)}: no NetworkPolicy allows ingress to its port "
                         f"{cp.get('name')} ({cp['containerPort']})")


def config_int(env: dict, key: str, where: str, w: dict) -> int | None:
    if key not in env:
        fail(f"{where} {ident(w)}: {key} is not set in the manifests (set it in configmap.yaml: "
             "the grace period is derived from it)")
        return None
    return int(env[key])


def check_grace_periods(r: Rendered, where: str) -> None:
    for w in r.of("Deployment"):
        spec = pod_spec(w) or {}
        grace = spec.get("terminationGracePeriodSeconds", 30)
        for c in containers(w):
            env, cmd = env_of(r, w, c), command_of(c)
            if cmd == "serve":
                timeout = config_int(env, "PANTOWATCH__HTTP__REQUEST_TIMEOUT_SECS", where, w)
                pre = ((c.get("lifecycle") or {}).get("preStop") or {})
                sleep = (pre.get("sleep") or {}).get("seconds", 0)
                cmdline = (pre.get("exec") or {}).get("command") or []
                if cmdline[:1] == ["sleep"] and len(cmdline) == 2:
                    sleep = int(cmdline[1])
                if timeout is not None and grace < sleep + timeout:
                    fail(f"{where} {ident(w)}: terminationGracePeriodSeconds {grace} < preStop {sleep} s "
                         f"+ http.request_timeout_secs {timeout} s: requests in flight are cut off")
            elif cmd == "worker":
                budget = config_int(env, "PANTOWATCH__WORKER__FIT_BUDGET_SECS", where, w)
                grace_ms = config_int(env, "PANTOWATCH__WORKER__SHUTDOWN_GRACE_MS", where, w)
                if budget is not None and grace_ms is not None and grace < budget + grace_ms / 1000:
                    fail(f"{where} {ident(w)}: terminationGracePeriodSeconds {grace} < worker.fit_budget_secs "
                         f"{budget} s + worker.shutdown_grace_ms {grace_ms / 1000:g} s: fits in flight are killed")


def check_settings_and_ports(r: Rendered, code: Code, where: str) -> None:
    for o in r.of("ConfigMap", "Secret"):
        for k in list((o.get("data") or {})) + list((o.get("stringData") or {})):
            if k.startswith("PANTOWATCH__") and k not in code.settings:
                fail(f"{where} {ident(o)}: {k} is not a setting of services/src/config.rs")
    for w in r.workloads():
        for c in containers(w):
            for e in c.get("env") or []:
                if e["name"].startswith("PANTOWATCH__") and e["name"] not in code.settings:
                    fail(f"{where} {ident(w)}: env {e['name']} is not a setting of services/src/config.rs")
            env, cmd = env_of(r, w, c), command_of(c)
            ports = {cp["containerPort"] for cp in c.get("ports") or []}
            if cmd == "serve":
                listen = port_of(env.get("PANTOWATCH__LISTEN", ""))
                args = (c.get("args") or [])
                if "--listen" in args:
                    listen = port_of(args[args.index("--listen") + 1])
                if listen not in ports:
                    fail(f"{where} {ident(w)}: the API listens on {listen}, not a containerPort {sorted(ports)}")
            if cmd == "worker" and ports:
                listen = port_of(env.get("PANTOWATCH__WORKER__METRICS_LISTEN", ""))
                if listen not in ports:
                    fail(f"{where} {ident(w)}: worker.metrics_listen port {listen} is not its containerPort "
                         f"{sorted(ports)}")


# Structural schemas of the CRD kinds used (fields as their CRDs define them; only what these
# manifests may use is allowed, unknown fields are errors as kubernetes-validate --strict makes them).
_META = {"type": "object", "required": ["name"],
         "properties": {"name": {"type": "string"}, "namespace": {"type": "string"},
                        "labels": {"type": "object", "additionalProperties": {"type": "string"}},
                        "annotations": {"type": "object", "additionalProperties": {"type": "string"}}},
         "additionalProperties": False}
_LABEL_SELECTOR = {"type": "object", "additionalProperties": False, "properties": {
    "matchLabels": {"type": "object", "additionalProperties": {"type": "string"}},
    "matchExpressions": {"type": "array", "items": {
        "type": "object", "required": ["key", "operator"], "additionalProperties": False,
        "properties": {"key": {"type": "string"},
                       "operator": {"enum": ["In", "NotIn", "Exists", "DoesNotExist"]},
                       "values": {"type": "array", "items": {"type": "string"}}}}}}}
_DURATION = {"type": "string", "pattern": r"^(0|(([0-9]+)y)?(([0-9]+)w)?(([0-9]+)d)?(([0-9]+)h)?(([0-9]+)m)?(([0-9]+)s)?(([0-9]+)ms)?)$"}
_RULE = {"type": "object", "required": ["expr"], "additionalProperties": False,
         "oneOf": [{"required": ["alert"]}, {"required": ["record"]}],
         "properties": {"alert": {"type": "string"}, "record": {"type": "string"},
                        "expr": {"type": ["string", "integer"]}, "for": _DURATION,
                        "keep_firing_for": _DURATION,
                        "labels": {"type": "object", "additionalProperties": {"type": "string"}},
                        "annotations": {"type": "object", "additionalProperties": {"type": "string"}}}}
_GROUPS = {"type": "array", "minItems": 1, "items": {
    "type": "object", "required": ["name", "rules"], "additionalProperties": False,
    "properties": {"name": {"type": "string"}, "interval": _DURATION, "limit": {"type": "integer"},
                   "rules": {"type": "array", "minItems": 1, "items": _RULE}}}}


def _cr(api: str, kind: str, spec: dict) -> dict:
    return {"type": "object", "required": ["apiVersion", "kind", "metadata", "spec"],
            "additionalProperties": False,
            "properties": {"apiVersion": {"const": api}, "kind": {"const": kind}, "metadata": _META,
                           "spec": spec}}


CRD_SCHEMAS = {
    ("monitoring.coreos.com/v1", "ServiceMonitor"): _cr("monitoring.coreos.com/v1", "ServiceMonitor", {
        "type": "object", "required": ["selector", "endpoints"], "additionalProperties": False,
        "properties": {
            "selector": _LABEL_SELECTOR, "jobLabel": {"type": "string"},
            "namespaceSelector": {"type": "object", "additionalProperties": False, "properties": {
                "any": {"type": "boolean"}, "matchNames": {"type": "array", "items": {"type": "string"}}}},
            "endpoints": {"type": "array", "minItems": 1, "items": {
                "type": "object", "required": ["port"], "additionalProperties": False,
                "properties": {"port": {"type": "string"}, "path": {"type": "string", "pattern": "^/"},
                               "scheme": {"enum": ["http", "https"]}, "interval": _DURATION,
                               "scrapeTimeout": _DURATION, "honorLabels": {"type": "boolean"}}}}}}),
    ("monitoring.coreos.com/v1", "PrometheusRule"): _cr("monitoring.coreos.com/v1", "PrometheusRule", {
        "type": "object", "required": ["groups"], "additionalProperties": False,
        "properties": {"groups": _GROUPS}}),
    ("keda.sh/v1alpha1", "ScaledObject"): _cr("keda.sh/v1alpha1", "ScaledObject", {
        "type": "object", "required": ["scaleTargetRef", "triggers"], "additionalProperties": False,
        "properties": {
            "scaleTargetRef": {"type": "object", "required": ["name"], "additionalProperties": False,
                               "properties": {"apiVersion": {"type": "string"}, "kind": {"type": "string"},
                                              "name": {"type": "string"},
                                              "envSourceContainerName": {"type": "string"}}},
            "pollingInterval": {"type": "integer", "minimum": 1},
            "cooldownPeriod": {"type": "integer", "minimum": 0},
            "idleReplicaCount": {"type": "integer", "minimum": 0},
            "minReplicaCount": {"type": "integer", "minimum": 0},
            "maxReplicaCount": {"type": "integer", "minimum": 1},
            "fallback": {"type": "object", "required": ["failureThreshold", "replicas"],
                         "additionalProperties": False,
                         "properties": {"failureThreshold": {"type": "integer", "minimum": 1},
                                        "replicas": {"type": "integer", "minimum": 0}}},
            "advanced": {"type": "object", "additionalProperties": False, "properties": {
                "restoreToOriginalReplicaCount": {"type": "boolean"},
                "horizontalPodAutoscalerConfig": {"type": "object", "additionalProperties": False,
                                                  "properties": {"name": {"type": "string"},
                                                                 "behavior": {"type": "object"}}}}},
            "triggers": {"type": "array", "minItems": 1, "items": {
                "type": "object", "required": ["type", "metadata"], "additionalProperties": False,
                "properties": {
                    "type": {"type": "string"}, "name": {"type": "string"},
                    "useCachedMetrics": {"type": "boolean"},
                    "metricType": {"enum": ["AverageValue", "Value", "Utilization"]},
                    # KEDA reads trigger metadata as strings: a bare number is refused.
                    "metadata": {"type": "object", "additionalProperties": {"type": "string"}},
                    "authenticationRef": {"type": "object", "required": ["name"], "additionalProperties": False,
                                          "properties": {"name": {"type": "string"},
                                                         "kind": {"enum": ["TriggerAuthentication",
                                                                           "ClusterTriggerAuthentication"]}}}}}}}}),
    ("keda.sh/v1alpha1", "TriggerAuthentication"): _cr("keda.sh/v1alpha1", "TriggerAuthentication", {
        "type": "object", "additionalProperties": False, "minProperties": 1,
        "properties": {"secretTargetRef": {"type": "array", "minItems": 1, "items": {
            "type": "object", "required": ["parameter", "name", "key"], "additionalProperties": False,
            "properties": {"parameter": {"type": "string"}, "name": {"type": "string"},
                           "key": {"type": "string"}}}}}}),
}


# ---- PromQL against the exported metrics --------------------------------------------------------

TARGET_LABELS = {"job", "instance", "namespace", "pod", "service", "container", "endpoint"}
BUILTIN_SERIES = {"up": {}, "scrape_duration_seconds": {}}
GRAFANA_VARS = re.compile(r"\$\{?__(rate_interval|interval|range)\}?")


def check_promql(where: str, expr: str, code: Code) -> set[str]:
    """Parses `expr` and checks every selector's metric, label names and literal label values
    against what the code exports; returns the metric names used."""
    try:
        tree = promql_parser.parse(GRAFANA_VARS.sub("5m", expr))
    except ValueError as e:
        fail(f"{where}: PromQL does not parse ({e}): {expr.strip()}")
        return set()
    used: set[str] = set()

    def series_labels(name: str) -> dict | None:
        if name in BUILTIN_SERIES:
            return {}
        return code.metrics.get(name)

    def selectors(node) -> list:
        found = []
        promql_parser.walk(node, lambda n: found.append(n) if type(n).__name__ == "VectorSelector" else None)
        return found

    def visit(n):
        t = type(n).__name__
        if t == "VectorSelector":
            name = n.name
            if name is None:
                fail(f"{where}: a selector without a metric name: {expr.strip()}")
                return True
            used.add(name)
            labels = series_labels(name)
            if labels is None:
                fail(f"{where}: metric {name} is not exported by services/src "
                     f"(exported: {', '.join(sorted(code.metrics))})")
                return True
            for m in n.matchers.matchers:
                if m.name == "__name__":
                    continue
                if m.name not in labels and m.name not in TARGET_LABELS:
                    fail(f"{where}: {name} has no label {m.name!r} (it has {sorted(labels) or 'none'})")
                    continue
                values = labels.get(m.name)
                if not values:
                    continue
                op = str(m.op).rsplit(".", 1)[-1]
                if op == "Equal" and m.value not in values:
                    fail(f"{where}: {name}{{{m.name}=\"{m.value}\"}} selects nothing: the code sets "
                         f"{m.name} to {sorted(values)}")
                if op == "Re":
                    alts = m.value.split("|")
                    plain = all(re.fullmatch(r"[A-Za-z0-9_]+", a) for a in alts)
                    missing = [a for a in alts if a not in values] if plain else \
                        ([] if any(re.fullmatch(m.value, v) for v in values) else [m.value])
                    if missing:
                        fail(f"{where}: {name}{{{m.name}=~\"{m.value}\"}}: {missing} never set by the code "
                             f"({sorted(values)})")
        elif t == "AggregateExpr" and n.modifier is not None and str(n.modifier.type).endswith("By"):
            inner = selectors(n.expr)
            have = set(TARGET_LABELS)
            for s in inner:
                have |= set((series_labels(s.name or "") or {}))
            for label in n.modifier.labels:
                if inner and label not in have:
                    fail(f"{where}: `by ({label})` groups on a label none of "
                         f"{sorted({s.name for s in inner})} has")
        return True

    promql_parser.walk(tree, visit)
    return used


def check_alerts(deploy: Path, code: Code) -> dict | None:
    path = deploy / ALERTS
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        fail(f"{ALERTS}: {e}")
        return None
    schema_errors = list(jsonschema.Draft7Validator(
        {"type": "object", "required": ["groups"], "additionalProperties": False,
         "properties": {"groups": _GROUPS}}).iter_errors(doc))
    for e in schema_errors:
        fail(f"{ALERTS}: {'/'.join(map(str, e.absolute_path)) or '(top)'}: {e.message}")
    if schema_errors:
        return doc
    names, used = set(), set()
    for g in doc["groups"]:
        for rule in g["rules"]:
            name = rule.get("alert") or rule.get("record")
            if name in names:
                fail(f"{ALERTS}: rule {name} defined twice")
            names.add(name)
            used |= check_promql(f"{ALERTS} {name}", str(rule["expr"]), code)
            if "alert" in rule:
                if (rule.get("labels") or {}).get("severity") not in ("info", "warning", "critical"):
                    fail(f"{ALERTS} {name}: labels.severity must be info, warning or critical")
                for a in ("summary", "description"):
                    if not (rule.get("annotations") or {}).get(a):
                        fail(f"{ALERTS} {name}: no {a} annotation")
    # Issue 18, point 6: queue age, failure rate, outbox backlog, no fits in N hours.
    for metric, topic in (("pantowatch_queue_oldest_job_age_seconds", "queue age"),
                          ("pantowatch_jobs_processed_total", "fit failure rate / no fits"),
                          ("pantowatch_webhook_outbox_backlog", "outbox backlog")):
        if metric not in used:
            fail(f"{ALERTS}: no rule on {metric} ({topic})")
    return doc


def check_prometheusrule_equals_alerts(where: str, pr: dict) -> None:
    alerts = yaml.safe_load((DEPLOY / ALERTS).read_text())
    if pr["spec"].get("groups") != (alerts or {}).get("groups"):
        fail(f"{where} {ident(pr)}: spec.groups differ from {ALERTS} "
             "(regenerate: deploy/check_kustomize.py --write-prometheusrule)")


def check_dashboard(deploy: Path, code: Code) -> None:
    path = deploy / DASHBOARD
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        fail(f"{DASHBOARD}: {e}")
        return
    for key in ("uid", "title", "panels", "schemaVersion", "templating"):
        if key not in d:
            fail(f"{DASHBOARD}: no {key}")
    if not isinstance(d.get("schemaVersion"), int) or d["schemaVersion"] < 36:
        fail(f"{DASHBOARD}: schemaVersion {d.get('schemaVersion')} (want ≥ 36)")
    variables = {v.get("name") for v in (d.get("templating") or {}).get("list") or []}
    ids, used = set(), set()
    panels = list(d.get("panels") or [])
    for p in list(panels):
        panels += p.get("panels") or []
    for p in panels:
        title = p.get("title", "?")
        if p.get("id") in ids:
            fail(f"{DASHBOARD}: panel id {p.get('id')} used twice")
        ids.add(p.get("id"))
        if "gridPos" not in p:
            fail(f"{DASHBOARD} {title!r}: no gridPos")
        if p.get("type") == "row":
            continue
        ds = json.dumps(p.get("datasource"))
        for v in re.findall(r"\$\{?(\w+)\}?", ds):
            if v not in variables:
                fail(f"{DASHBOARD} {title!r}: datasource variable ${v} is not defined in templating")
        if not p.get("targets"):
            fail(f"{DASHBOARD} {title!r}: no queries")
        for t in p.get("targets") or []:
            used |= check_promql(f"{DASHBOARD} {title!r}", t.get("expr", ""), code)
    want = {"pantowatch_fit_duration_seconds_bucket": "fit duration quantiles",
            "pantowatch_jobs": "queue depth",
            "pantowatch_queue_oldest_job_age_seconds": "oldest job age",
            "pantowatch_jobs_processed_total": "attempts",
            "pantowatch_jobs_failed_total": "failures by reason",
            "pantowatch_webhook_outbox_backlog": "outbox backlog",
            "http_requests_total": "request rate",
            "http_request_duration_seconds_bucket": "request latency"}
    for metric, what in want.items():
        if metric not in used:
            fail(f"{DASHBOARD}: no panel on {metric} ({what})")
    unused = {n for n in code.metrics if not n.endswith(("_sum", "_count"))} - used
    if unused:
        print(f"check_kustomize.py: note: exported but not on the dashboard: {', '.join(sorted(unused))}",
              file=sys.stderr)


# ---- compose and Dockerfile ----------------------------------------------------------------------

def devtcp_port_path(test) -> tuple[int | None, str | None]:
    text = " ".join(test) if isinstance(test, list) else str(test)
    port = re.search(r"/dev/tcp/[^/\s]+/(\d+)", text)
    path = re.search(r"GET (\S+) HTTP", text)
    return (int(port.group(1)) if port else None, path.group(1) if path else None)


def check_compose(deploy: Path, code: Code) -> None:
    path = deploy / "compose.yaml"
    c = yaml.safe_load(path.read_text())
    svc = c.get("services") or {}
    for name in ("api", "worker"):
        s = svc.get(name) or {}
        env = {k: str(v) for k, v in (s.get("environment") or {}).items()}
        hc = (s.get("healthcheck") or {}).get("test")
        if not hc:
            fail(f"compose.yaml: service {name} has no healthcheck")
            continue
        port, hpath = devtcp_port_path(hc)
        cmd = s.get("command") or []
        if name == "api":
            listen = port_of(cmd[cmd.index("--listen") + 1]) if "--listen" in cmd else port_of(env.get("PANTOWATCH__LISTEN", ""))
            served = code.api_paths
        else:
            listen = port_of(env.get("PANTOWATCH__WORKER__METRICS_LISTEN", ""))
            served = code.worker_paths
        if listen is None or port != listen:
            fail(f"compose.yaml: {name} healthcheck probes port {port}, the process listens on {listen}")
        if hpath not in served:
            fail(f"compose.yaml: {name} healthcheck asks for {hpath}, which `pantowatch "
                 f"{'serve' if name == 'api' else 'worker'}` does not serve")
        image = str(s.get("image", ""))
        m = re.fullmatch(r"pantowatch:\$\{PANTOWATCH_VERSION:-([^}]+)\}", image)
        if not m or m.group(1) != code.version:
            fail(f"compose.yaml: {name} image {image!r} is not pantowatch:${{PANTOWATCH_VERSION:-{code.version}}}")
        arg = str(((s.get("build") or {}).get("args") or {}).get("VERSION", ""))
        if arg != image.split(":", 1)[-1]:
            fail(f"compose.yaml: {name} build arg VERSION {arg!r} does not match its image tag")
    prom = svc.get("prometheus") or {}
    mounts = {}
    for v in prom.get("volumes") or []:
        host, ctr = str(v).split(":")[:2]
        mounts[ctr] = (deploy / host).resolve()
    cfg_file = mounts.get("/etc/prometheus/prometheus.yml")
    if not cfg_file or not cfg_file.is_file():
        fail("compose.yaml: prometheus does not mount an existing prometheus.yml")
        return
    cfg = yaml.safe_load(cfg_file.read_text())
    rules = cfg.get("rule_files") or []
    if not rules:
        fail(f"{cfg_file.name}: no rule_files")
    for rf in rules:
        if mounts.get(rf) != (deploy / ALERTS).resolve():
            fail(f"compose.yaml: prometheus rule file {rf} is not {ALERTS} mounted there")
    scraped = {}
    for sc in cfg.get("scrape_configs") or []:
        for sd in sc.get("dns_sd_configs") or []:
            for n in sd.get("names") or []:
                scraped[n] = (sd.get("port"), sc.get("metrics_path", "/metrics"))
    for name, want in (("api", 8080), ("worker", port_of(str((svc.get("worker") or {}).get("environment", {}).get("PANTOWATCH__WORKER__METRICS_LISTEN", ""))))):
        if scraped.get(name, (None,))[0] != want:
            fail(f"{cfg_file.name}: service {name} is not scraped on its metrics port {want}")


def check_dockerfile(repo: Path, code: Code) -> None:
    text = (repo / "Dockerfile").read_text()
    if not re.search(r"^ARG VERSION\b", text, re.M):
        fail("Dockerfile: no ARG VERSION")
    for label in ("org.opencontainers.image.version=\"${VERSION}\"", "org.opencontainers.image.revision=\"${REVISION}\""):
        if label not in text:
            fail(f"Dockerfile: no LABEL {label}")
    if "pantowatch:latest" in text:
        fail("Dockerfile: names pantowatch:latest")


# ---- main ------------------------------------------------------------------------------------------

def write_prometheusrule(deploy: Path) -> None:
    path = deploy / PROMETHEUSRULE
    head = path.read_text().split("\nspec:\n")[0] + "\nspec:\n"
    groups = (deploy / ALERTS).read_text().split("\ngroups:\n", 1)[1]
    body = "groups:\n" + groups
    path.write_text(head + "".join("  " + line if line.strip() else line
                                   for line in body.splitlines(keepends=True)))
    print(f"check_kustomize.py: wrote {path}", file=sys.stderr)


def compare_kubectl(d: Path, mine: list[dict]) -> None:
    out = subprocess.run(["kubectl", "kustomize", str(d)], capture_output=True, text=True)
    if out.returncode != 0:
        fail(f"kubectl kustomize {d}: {out.stderr.strip()}")
        return
    theirs = [x for x in yaml.safe_load_all(out.stdout) if x]
    ours = [clean(o) for o in legacy_sorted(mine)]
    if [ident(o) for o in theirs] != [ident(o) for o in ours]:
        fail(f"kubectl kustomize {d} renders {[ident(o) for o in theirs]}, check_kustomize.py "
             f"{[ident(o) for o in ours]}")
    for a, b in zip(theirs, ours):
        if a != b:
            fail(f"kubectl kustomize {d}: {ident(a)} differs:\n  kubectl: {json.dumps(a, sort_keys=True)}\n"
                 f"  ours:    {json.dumps(b, sort_keys=True)}")
    if not errors:
        print(f"check_kustomize.py: {d.name}: identical to `kubectl kustomize` "
              f"({len(theirs)} objects)", file=sys.stderr)


def main() -> int:
    here = Path(__file__).resolve().parent
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--deploy", type=Path, default=here, help="the deploy/ directory to check")
    ap.add_argument("--repo", type=Path, default=here.parent,
                    help="the repository (Cargo.toml, services/src, migrations, Dockerfile)")
    ap.add_argument("--out", type=Path, help="write each rendering here: <name>.all.yaml, and "
                                             "<name>.yaml with the built-in kinds only (for kubernetes-validate)")
    ap.add_argument("--compare-kubectl", action="store_true",
                    help="also compare each rendering with `kubectl kustomize` (needs kubectl)")
    ap.add_argument("--write-prometheusrule", action="store_true",
                    help=f"regenerate {PROMETHEUSRULE} from {ALERTS} and exit")
    a = ap.parse_args()
    global DEPLOY
    deploy, repo = a.deploy.resolve(), a.repo.resolve()
    DEPLOY = deploy
    if a.write_prometheusrule:
        write_prometheusrule(deploy)
        return 0
    code = Code(repo)
    renderings = []
    for name in [BASE, *OVERLAYS]:
        try:
            objs, k = build(deploy / name, "Kustomization")
        except (RenderError, OSError) as e:
            fail(f"{name}: cannot render: {e}")
            continue
        r = Rendered(name, objs, k)
        renderings.append(r)
        check_rendering(r, code, base=(name == BASE))
        if a.out:
            a.out.mkdir(parents=True, exist_ok=True)
            rendered = [clean(o) for o in legacy_sorted(objs)]
            (a.out / f"{name}.all.yaml").write_text(yaml.safe_dump_all(rendered, sort_keys=False))
            builtin = [o for o in rendered if is_builtin(o["apiVersion"])]
            (a.out / f"{name}.yaml").write_text(yaml.safe_dump_all(builtin, sort_keys=False))
        if a.compare_kubectl:
            compare_kubectl(deploy / name, copy.deepcopy(objs))
    check_alerts(deploy, code)
    check_dashboard(deploy, code)
    check_compose(deploy, code)
    check_dockerfile(repo, code)
    if errors:
        for e in errors:
            print(f"check_kustomize.py: {e}", file=sys.stderr)
        print(f"check_kustomize.py: {len(errors)} problem(s)", file=sys.stderr)
        return 1
    summary = ", ".join(f"{r.name} {len(r.objs)} objects" for r in renderings)
    print(f"check_kustomize.py: {summary}; version {code.version}; "
          f"{len(code.metrics)} exported series; all references resolve", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
