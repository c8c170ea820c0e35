# nuno: multi-stage build. The builder fetches the MuJoCo runtime exactly like
# the Makefile does (libmujoco from the `mujoco` wheel, MJCF from `gymnasium`).
#
# Where no image hub is reachable, `make check-docker` builds both stages on a
# local Debian bookworm base (debootstrap + docker import) and hands the builder
# the binaries it built on the host (same Debian release) in .docker-dist/.
ARG BUILD_IMAGE=rust:1.95-bookworm
ARG RUNTIME_IMAGE=debian:bookworm-slim

FROM ${BUILD_IMAGE} AS builder
# The same absolute path in both stages, since binaries carry it as their rpath.
WORKDIR /opt/nuno
COPY . .
RUN if [ -f .docker-dist/nuno-server ]; then \
      mkdir -p target/release \
      && cp .docker-dist/nuno-server .docker-dist/nuno-trainer target/release/ \
      && test -f .mujoco/lib/libmujoco.so; \
    else \
      apt-get update \
      && apt-get install -y --no-install-recommends python3 python3-pip python3-venv make pkg-config libhdf5-dev \
      && rm -rf /var/lib/apt/lists/* \
      && make mujoco \
      && CARGO_PROFILE_RELEASE_STRIP=debuginfo cargo build --release --workspace --locked; \
    fi

FROM ${RUNTIME_IMAGE} AS runtime
RUN apt-get update \
 && apt-get install -y --no-install-recommends libhdf5-103-1 curl \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --home-dir /opt/nuno nuno
WORKDIR /opt/nuno
COPY --from=builder /opt/nuno/.mujoco/lib /opt/nuno/.mujoco/lib
COPY --from=builder /opt/nuno/target/release/nuno-server /usr/local/bin/nuno-server
COPY --from=builder /opt/nuno/target/release/nuno-trainer /usr/local/bin/nuno-trainer
COPY --from=builder /opt/nuno/models /opt/nuno/models
# Host-built binaries carry the host's rpath; this one holds in the image.
ENV LD_LIBRARY_PATH=/opt/nuno/.mujoco/lib
USER nuno
# REST on 8080; the Open Inference Protocol over gRPC on 8081.
EXPOSE 8080 8081
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s CMD ["curl", "-fsS", "http://127.0.0.1:8080/healthz"]
# SIGTERM shuts down gracefully; SIGHUP (docker kill -s HUP) reloads the models.
CMD ["nuno-server", "--models", "/opt/nuno/models", "--addr", "0.0.0.0:8080", "--grpc-addr", "0.0.0.0:8081"]
