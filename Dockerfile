# nuno: multi-stage build. The builder fetches the MuJoCo runtime exactly like
# the Makefile does (libmujoco from the `mujoco` wheel, MJCF from `gymnasium`).
FROM rust:1.95-bookworm AS builder
RUN apt-get update \
 && apt-get install -y --no-install-recommends python3 python3-pip python3-venv make pkg-config libhdf5-dev \
 && rm -rf /var/lib/apt/lists/*
# The same absolute path in both stages, since binaries carry it as their rpath.
WORKDIR /opt/nuno
COPY . .
RUN make mujoco && cargo build --release --workspace --locked

FROM debian:bookworm-slim AS runtime
RUN apt-get update \
 && apt-get install -y --no-install-recommends libhdf5-103-1 curl \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --home-dir /opt/nuno nuno
WORKDIR /opt/nuno
COPY --from=builder /opt/nuno/.mujoco/lib /opt/nuno/.mujoco/lib
COPY --from=builder /opt/nuno/target/release/nuno-server /usr/local/bin/nuno-server
COPY --from=builder /opt/nuno/target/release/nuno-trainer /usr/local/bin/nuno-trainer
COPY --from=builder /opt/nuno/models /opt/nuno/models
USER nuno
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s CMD ["curl", "-fsS", "http://127.0.0.1:8080/healthz"]
# SIGTERM shuts down gracefully; SIGHUP (docker kill -s HUP) reloads the models.
CMD ["nuno-server", "--models", "/opt/nuno/models", "--addr", "0.0.0.0:8080"]
