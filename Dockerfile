# pantowatch: the service, worker and CLI in one image (`pantowatch serve|worker|migrate|keys`).
# Multi-stage: a release build in the Rust image, then only the binary on Debian slim, run as an
# unprivileged user (uid 10001) with no writable path it needs (PostgreSQL holds all state).
#
# The image is tagged with the workspace version of Cargo.toml, which the build checks:
#
#   VERSION=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml)
#   docker build --build-arg VERSION=$VERSION --build-arg REVISION=$(git rev-parse HEAD) \
#       -t pantowatch:$VERSION .
#   docker run --rm pantowatch:$VERSION --help
#
# (deploy/build-image.sh does exactly this.) deploy/k8s and deploy/compose.yaml run
# pantowatch:<that version>, never :latest, and the Kubernetes migration Job is named after it.

# ---- build -----------------------------------------------------------------------------------
FROM rust:1.95-bookworm AS build
WORKDIR /src
# The whole workspace manifest set (cargo resolves every member), then the sources.
COPY Cargo.toml Cargo.lock ./
# The tag must name the version being built (a suffix is allowed: 0.1.0-rc1, 0.1.0-3f2a9c1).
ARG VERSION
RUN cargo_version=$(sed -n '/^\[workspace.package\]/,/^\[/s/^version = "\(.*\)"/\1/p' Cargo.toml) \
    && case "$VERSION" in \
         "$cargo_version"|"$cargo_version"-*) ;; \
         *) echo "--build-arg VERSION='$VERSION' is not Cargo.toml's version $cargo_version" >&2; exit 1 ;; \
       esac
COPY models ./models
COPY services ./services
COPY tools ./tools
COPY tests ./tests
COPY migrations ./migrations
# --locked: the image builds exactly the committed dependency graph.
RUN cargo build --release --locked -p pantowatch --bin pantowatch \
    && cp target/release/pantowatch /usr/local/bin/pantowatch \
    && strip /usr/local/bin/pantowatch

# ---- run -------------------------------------------------------------------------------------
FROM debian:bookworm-slim
# CA roots for webhook receivers over HTTPS (PostgreSQL TLS uses the roots compiled into sqlx,
# or `sslrootcert=` in the database URL).
RUN apt-get update \
    && apt-get install -y --no-install-recommends ca-certificates \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10001 --no-create-home --shell /usr/sbin/nologin pantowatch
COPY --from=build /usr/local/bin/pantowatch /usr/local/bin/pantowatch
# Declared after the cached layers: a new revision relabels the image, it does not rebuild it.
ARG VERSION
ARG REVISION=unknown
LABEL org.opencontainers.image.title="pantowatch" \
      org.opencontainers.image.description="Pantograph joint wear: trace upload, friction fits, drift alerts" \
      org.opencontainers.image.version="${VERSION}" \
      org.opencontainers.image.revision="${REVISION}" \
      org.opencontainers.image.licenses="MIT"
USER 10001:10001
# In a container the API must listen on every interface; everything else comes from
# PANTOWATCH__* variables (deploy/pantowatch.example.toml lists them all).
ENV PANTOWATCH__LISTEN=0.0.0.0:8080 \
    PANTOWATCH__LOG__FORMAT=json
# 8080: the API (`serve`); 9464: a worker's /metrics and /healthz when worker.metrics_listen is set.
EXPOSE 8080 9464
ENTRYPOINT ["/usr/local/bin/pantowatch"]
CMD ["serve", "--workers", "0"]
