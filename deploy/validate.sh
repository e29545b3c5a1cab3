#!/usr/bin/env bash
# Validates deploy/ without a container engine or a cluster, offline once the tools are there:
#   - compose.yaml with `docker compose config -q` (or docker-compose v1 from Debian apt);
#   - k8s/*.yaml against the Kubernetes JSON schemas bundled in PyPI `kubernetes-validate`
#     (--strict: unknown fields are errors);
#   - the health/metrics paths the manifests probe exist in services/openapi.json;
# and proves each validator rejects a deliberately broken copy (a check that cannot fail is none).
# Installs its tools when missing, as .ci/run installs chromium (root on a Debian CI machine).
set -euo pipefail
cd "$(dirname "$0")"

KUBERNETES_VALIDATE_VERSION=1.37.0

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

# The compose file refuses to render without these (credentials never live in the file).
export POSTGRES_PASSWORD=validate-only PANTOWATCH_SESSION_SECRET=validate-only

fail() { echo "deploy/validate.sh: $*" >&2; exit 1; }

# --- compose ------------------------------------------------------------------------------------
"${compose[@]}" -f compose.yaml config -q || fail "compose.yaml is invalid"
services=$("${compose[@]}" -f compose.yaml config --services | sort | tr '\n' ' ')
[ "$services" = "api migrate postgres prometheus worker " ] \
    || fail "compose.yaml services are '$services'"

# --- Kubernetes -----------------------------------------------------------------------------------
python3 -m kubernetes_validate --strict --quiet k8s/*.yaml || fail "k8s manifests are invalid"
for kind in Namespace ConfigMap Secret Job Deployment Service HorizontalPodAutoscaler; do
    grep -qx "kind: $kind" k8s/*.yaml || fail "no $kind in k8s/"
done
for path in /healthz /readyz /metrics; do
    grep -q "\"$path\"" ../services/openapi.json || fail "$path is probed but not served"
done

# --- negative checks: each validator must reject a broken copy --------------------------------
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cp compose.yaml prometheus.yml "$tmp/"
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

echo "deploy/validate.sh: compose.yaml and k8s/ valid; broken copies rejected"
