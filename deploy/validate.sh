#!/usr/bin/env bash
# Validates deploy/ without a container engine, kubectl or a cluster, offline once the tools are
# there:
#   - compose.yaml with `docker compose config -q` (or docker-compose v1 from Debian apt);
#   - check_kustomize.py: renders deploy/k8s (the base: applies to an empty cluster in one go) and
#     deploy/k8s-operators (+ KEDA and Prometheus-operator objects) as kustomize does, and checks
#     ordering, references, image tags, grace periods against the configured budgets, network
#     policy, autoscalers, the CRD kinds' fields, the alert rules and dashboard against the
#     metrics the code exports, compose's healthchecks and Prometheus wiring;
#   - the rendered built-in objects against the Kubernetes JSON schemas bundled in PyPI
#     `kubernetes-validate` (--strict: unknown fields are errors);
#   - the health/metrics paths the manifests probe exist in services/openapi.json;
# and proves each validator rejects deliberately broken copies (a check that cannot fail is none).
# Installs its tools when missing, as .ci/run installs chromium (root on a Debian CI machine):
# docker-compose (apt), kubernetes-validate (brings PyYAML and jsonschema) and promql-parser
# (PromQL parser, a binary wheel) from PyPI, pinned. Nothing is downloaded once they are there.
set -euo pipefail
cd "$(dirname "$0")"

KUBERNETES_VALIDATE_VERSION=1.37.0
PROMQL_PARSER_VERSION=0.12.0

if docker compose version >/dev/null 2>&1; then
    compose=(docker compose)
else
    if ! command -v docker-compose >/dev/null; then
        apt-get update -qq
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker-compose >/dev/null
    fi
    compose=(docker-compose)
fi
if ! python3 -m kubernetes_validate --version >/dev/null 2>&1; then
    python3 -m pip install -q --disable-pip-version-check \
        "kubernetes-validate==${KUBERNETES_VALIDATE_VERSION}"
fi
if ! python3 -c 'import promql_parser' >/dev/null 2>&1; then
    python3 -m pip install -q --disable-pip-version-check "promql-parser==${PROMQL_PARSER_VERSION}"
fi

# The compose file refuses to render without these (credentials never live in the file).
export POSTGRES_PASSWORD=validate-only PANTOWATCH_SESSION_SECRET=validate-only

fail() { echo "deploy/validate.sh: $*" >&2; exit 1; }

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# --- compose ------------------------------------------------------------------------------------
"${compose[@]}" -f compose.yaml config -q || fail "compose.yaml is invalid"
services=$("${compose[@]}" -f compose.yaml config --services | sort | tr '\n' ' ')
[ "$services" = "api migrate postgres prometheus worker " ] \
    || fail "compose.yaml services are '$services'"

# --- Kubernetes: render and check, then the schemas -------------------------------------------
python3 check_kustomize.py --out "$tmp/rendered" || fail "check_kustomize.py found problems"
for r in k8s k8s-operators; do
    python3 -m kubernetes_validate --strict --quiet "$tmp/rendered/$r.yaml" \
        || fail "the objects of $r are invalid"
done
for kind in Namespace ConfigMap Secret Job Deployment Service HorizontalPodAutoscaler \
        PodDisruptionBudget NetworkPolicy; do
    grep -qx "kind: $kind" "$tmp/rendered/k8s.all.yaml" || fail "no $kind in k8s/"
done
for kind in ScaledObject TriggerAuthentication ServiceMonitor PrometheusRule; do
    grep -qx "kind: $kind" "$tmp/rendered/k8s-operators.all.yaml" || fail "no $kind in k8s-operators/"
done
for path in /healthz /readyz /metrics; do
    grep -q "\"$path\"" ../services/openapi.json || fail "$path is probed but not served"
done

# --- negative checks: each validator must reject a broken copy --------------------------------
cp compose.yaml "$tmp/"
cp -r prometheus "$tmp/"
sed -i 's/replicas: 2/replicas: two/' "$tmp/compose.yaml"
cmp -s compose.yaml "$tmp/compose.yaml" && fail "negative check: the compose copy is not broken"
if "${compose[@]}" -f "$tmp/compose.yaml" config -q >/dev/null 2>&1; then
    fail "negative check: a compose file with 'replicas: two' was accepted"
fi
sed 's/containerPort: 8080/containerPort: "eighty"/' k8s/api-deployment.yaml >"$tmp/api.yaml"
cmp -s k8s/api-deployment.yaml "$tmp/api.yaml" && fail "negative check: the manifest copy is not broken"
if python3 -m kubernetes_validate --strict --quiet "$tmp/api.yaml" >/dev/null 2>&1; then
    fail "negative check: a Deployment with containerPort \"eighty\" was accepted"
fi
sed 's/^      containers:/      contaners:/' k8s/worker-deployment.yaml >"$tmp/worker.yaml"
cmp -s k8s/worker-deployment.yaml "$tmp/worker.yaml" && fail "negative check: the worker copy is not broken"
if python3 -m kubernetes_validate --strict --quiet "$tmp/worker.yaml" >/dev/null 2>&1; then
    fail "negative check: a Deployment with a misspelt 'containers' was accepted"
fi

# check_kustomize.py on copies of deploy/, each broken once; it must refuse the copy, and for the
# reason the break introduces (its message), not another one.
broken=0
rejects() {
    local expect=$1 file=$2
    shift 2
    rm -rf "$tmp/d"
    mkdir "$tmp/d"
    cp -r . "$tmp/d/"
    (cd "$tmp/d" && eval "$*")
    cmp -s "$file" "$tmp/d/$file" && fail "negative check: '$*' did not change $file"
    local out
    if out=$(python3 check_kustomize.py --deploy "$tmp/d" --repo .. 2>&1); then
        fail "negative check: accepted a copy broken by: $*"
    fi
    grep -qF -- "$expect" <<<"$out" \
        || fail "negative check: '$*' was refused, but not with '$expect':"$'\n'"$out"
    broken=$((broken + 1))
}
rejects "not the Namespace" k8s/kustomization.yaml \
    "sed -i '/^  - namespace.yaml\$/d' k8s/kustomization.yaml && echo '  - namespace.yaml' >>k8s/kustomization.yaml"
rejects "envFrom configMapRef 'pantowatch-confg' does not exist" k8s/api-deployment.yaml \
    "sed -i 's/name: pantowatch-config/name: pantowatch-confg/' k8s/api-deployment.yaml"
rejects "fits in flight are killed" k8s/worker-deployment.yaml \
    "sed -i 's/terminationGracePeriodSeconds: 80/terminationGracePeriodSeconds: 30/' k8s/worker-deployment.yaml"
rejects "requests in flight are cut off" k8s/configmap.yaml \
    "sed -i 's/REQUEST_TIMEOUT_SECS: \"60\"/REQUEST_TIMEOUT_SECS: \"120\"/' k8s/configmap.yaml"
rejects "is untagged or :latest" k8s/worker-deployment.yaml \
    "sed -i 's/image: pantowatch:.*/image: pantowatch:latest/' k8s/worker-deployment.yaml"
rejects "a migration Job per image tag" k8s/migrate-job.yaml \
    "sed -i 's/name: pantowatch-migrate-.*/name: pantowatch-migrate/' k8s/migrate-job.yaml"
rejects "needs a CRD" k8s/kustomization.yaml \
    "echo '  - components/prometheus-operator/servicemonitor.yaml' >>k8s/kustomization.yaml"
rejects "has 2 autoscalers" k8s/components/keda/kustomization.yaml \
    "sed -i '/^patches:/,\$d' k8s/components/keda/kustomization.yaml"
rejects "scaleTargetRef Deployment 'pantowatch-workers' does not exist" k8s/components/keda/scaledobject.yaml \
    "sed -i 's/name: pantowatch-worker\$/name: pantowatch-workers/' k8s/components/keda/scaledobject.yaml"
rejects "is not a port name of" k8s/components/prometheus-operator/servicemonitor.yaml \
    "sed -i 's/port: metrics/port: metric/' k8s/components/prometheus-operator/servicemonitor.yaml"
rejects "allows egress TCP/5432 (PostgreSQL)" k8s/networkpolicy.yaml \
    "sed -i 's/port: 5432/port: 5433/' k8s/networkpolicy.yaml"
rejects "metric pantowatch_webhook_outbox_backlogg is not exported" prometheus/alerts.yml \
    "sed -i 's/pantowatch_webhook_outbox_backlog)/pantowatch_webhook_outbox_backlogg)/' prometheus/alerts.yml"
rejects 'selects nothing' prometheus/alerts.yml \
    "sed -i 's/outcome=\"done\"/outcome=\"completed\"/' prometheus/alerts.yml"
rejects "spec.groups differ from prometheus/alerts.yml" k8s/components/prometheus-operator/prometheusrule.yaml \
    "sed -i '0,/for: 5m/s//for: 6m/' k8s/components/prometheus-operator/prometheusrule.yaml"
rejects "metric pantowatch_queue_oldest_age_seconds is not exported" grafana/pantowatch-dashboard.json \
    "sed -i 's/pantowatch_queue_oldest_job_age_seconds/pantowatch_queue_oldest_age_seconds/' grafana/pantowatch-dashboard.json"
rejects "api healthcheck probes port 8081" compose.yaml \
    "sed -i 's|/dev/tcp/127.0.0.1/8080|/dev/tcp/127.0.0.1/8081|' compose.yaml"

echo "deploy/validate.sh: compose.yaml and k8s/ valid; 3 broken copies refused by the schemas," \
    "$broken by check_kustomize.py"
