#!/usr/bin/env bash
# Writes Cargo.toml's workspace version (or the one given) into every deploy file that names the
# image tag: the kustomization's newTag, the image of each manifest, the migration Job's name
# (dots as dashes: one Job per version) and compose's default tag. deploy/check_kustomize.py
# fails when one of them differs from Cargo.toml, so run this after bumping the version.
#   deploy/set-version.sh            # Cargo.toml's version
#   deploy/set-version.sh 0.2.0
set -euo pipefail
cd "$(dirname "$0")"
version=${1:-$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' ../Cargo.toml)}
[[ "$version" =~ ^[0-9]+\.[0-9]+\.[0-9]+(-[0-9A-Za-z.-]+)?$ ]] \
    || { echo "set-version.sh: '$version' is not a version" >&2; exit 1; }
slug=$(echo "$version" | tr '.' '-' | tr 'A-Z' 'a-z')
sed -i -E "s/^(    newTag: )\"[^\"]*\"/\1\"$version\"/" k8s/kustomization.yaml
sed -i -E "s/^(  name: pantowatch-migrate-).*/\1$slug/" k8s/migrate-job.yaml
sed -i -E "s/^(          image: pantowatch:).*/\1$version/" k8s/*.yaml
sed -i -E "s/(PANTOWATCH_VERSION:-)[^}]*\}/\1$version}/g" compose.yaml
echo "set-version.sh: deploy/ now names $version (check: python3 deploy/check_kustomize.py)" >&2
