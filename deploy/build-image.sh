#!/usr/bin/env bash
# Builds the pantowatch image tagged with Cargo.toml's workspace version (what deploy/k8s and
# deploy/compose.yaml run), labelled with the git revision:
#   deploy/build-image.sh                          # pantowatch:<version>
#   IMAGE=registry.example/pantowatch deploy/build-image.sh --push
# Extra arguments go to `docker build` (BuildKit's --push, --platform, ...).
set -euo pipefail
cd "$(dirname "$0")/.."
version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
[ -n "$version" ] || { echo "build-image.sh: no [workspace.package] version in Cargo.toml" >&2; exit 1; }
revision=$(git rev-parse HEAD 2>/dev/null || echo unknown)
if [ -n "$(git status --porcelain 2>/dev/null)" ]; then
    revision="$revision-dirty"
fi
image="${IMAGE:-pantowatch}:$version"
echo "build-image.sh: $image (revision $revision)" >&2
docker build --build-arg "VERSION=$version" --build-arg "REVISION=$revision" -t "$image" "$@" .
