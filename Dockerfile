# pantowatch: the service, worker and CLI in one image (`pantowatch serve|worker|migrate|keys`).
# Multi-stage: a release build in the Rust image, then only the binary on Debian slim, run as an
# unprivileged user (uid 10001) with no writable path it needs (PostgreSQL holds all state).
#
#   docker build -t pantowatch:latest .
#   docker run --rm pantowatch:latest --help

# ---- build -----------------------------------------------------------------------------------
FROM rust:1.95-bookworm AS build
WORKDIR /src
# The whole workspace manifest set (cargo resolves every member), then the sources.
COPY Cargo.toml Cargo.lock ./
COPY models ./models
COPY services ./services
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
USER 10001:10001
# In a container the API must listen on every interface; everything else comes from
# PANTOWATCH__* variables (deploy/pantowatch.example.toml lists them all).
ENV PANTOWATCH__LISTEN=0.0.0.0:8080 \
    PANTOWATCH__LOG__FORMAT=json
EXPOSE 8080
ENTRYPOINT ["/usr/local/bin/pantowatch"]
CMD ["serve", "--workers", "0"]
