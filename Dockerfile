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
 && apt-get install -y --no-install-recommends libhdf5-103-1 \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --home-dir /opt/nuno nuno
WORKDIR /opt/nuno
COPY --from=builder /opt/nuno/.mujoco/lib /opt/nuno/.mujoco/lib
COPY --from=builder /opt/nuno/target/release/nuno-trainer /usr/local/bin/nuno-trainer
COPY --from=builder /opt/nuno/models /opt/nuno/models
USER nuno
HEALTHCHECK --interval=30s --timeout=10s CMD ["nuno-trainer", "--version"]
CMD ["nuno-trainer", "evaluate", "--policy", "random", "--task", "hopper", "--episodes", "10"]
