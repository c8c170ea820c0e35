# nuno: `make serve` and `make test` are the two commands a fresh machine needs.
# Everything else they depend on (the MuJoCo runtime from PyPI wheels, the Python
# venv the parity tests compare against) is fetched here, once.

MUJOCO_VERSION    := 3.17.0
GYMNASIUM_VERSION := 1.2.2
PYTHON            ?= python3
CARGO             ?= cargo
MUJOCO_DIR        := .mujoco
MUJOCO_LIB        := $(MUJOCO_DIR)/lib/libmujoco.so
MJCF_DIR          := $(MUJOCO_DIR)/assets
MJCF_FILES        := $(addprefix $(MJCF_DIR)/,hopper.xml half_cheetah.xml walker2d.xml swimmer.xml \
                       inverted_pendulum.xml ant.xml)
VENV              := .venv
VENV_STAMP        := $(VENV)/.installed
# Any wheel of the pinned release carries the same libmujoco; take the one for this Python.
PIP_DOWNLOAD      := $(PYTHON) -m pip download --quiet --no-deps --only-binary=:all:

# Where cargo puts its build (CARGO_TARGET_DIR or the workspace's target/), read when needed.
TARGET_DIR    = $(shell $(CARGO) metadata --format-version 1 --no-deps | $(PYTHON) -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')

# The suite with the tests that need the venv, Slurm and the Kubernetes schemas
# (`cargo test --workspace` alone lists them as ignored, saying why). `make serve`
# builds with the same features, so either command reuses the other's build.
SUITE        := --workspace --release --features nuno-trainer/external-tests

SERVE_ADDR   ?= 127.0.0.1:8080
SERVE_MODELS ?= models

.PHONY: serve test mujoco venv system-deps slurm build lint bench openapi check-wgpu check-docker clean-runtime

## serve: fetch what is missing, build, and serve the shipped models on $(SERVE_ADDR).
## The server is the binary `make test` builds (`cargo test --no-run` builds it for the
## integration tests): `cargo run` would resolve the dependencies' features without the
## dev-dependencies and compile a second tree, so either command reuses the other's build.
serve: mujoco
	$(CARGO) test $(SUITE) --no-run
	"$(TARGET_DIR)/release/nuno-server" --models $(SERVE_MODELS) --addr $(SERVE_ADDR)

## test: the full suite (unit, integration, Gymnasium parity), then the fused
## kernels' numerics again on each narrower vector level (NUNO_SIMD), so every
## variant runs whatever the machine's widest is (--workspace: the same build as above).
test: mujoco venv slurm
	$(CARGO) test $(SUITE)
	for level in portable avx2; do \
	  NUNO_SIMD=$$level $(CARGO) test $(SUITE) --lib infer:: || exit 1; \
	  NUNO_SIMD=$$level $(CARGO) test $(SUITE) --test infer || exit 1; \
	done

build: mujoco
	$(CARGO) build --workspace --release

lint: mujoco
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets --release -- -D warnings
	# The library alone, as a dependency with default-features = false: no server stack.
	$(CARGO) clippy --lib --no-default-features --release -- -D warnings

bench: mujoco
	$(CARGO) bench --bench env_step
	$(CARGO) bench --bench sde
	$(CARGO) bench --bench infer
	$(CARGO) bench --bench sac

## openapi: regenerate the committed spec (a test fails when it is stale).
openapi: mujoco
	$(CARGO) run --release --bin nuno-server -- --print-openapi > openapi/openapi.json

## check-docker: build the image from the Dockerfile and check it runs as deployed
## (ready, a step, gRPC live, SIGHUP reload, SIGTERM exit 0, non-root); prints the image size.
## Needs a docker daemon (or root and Debian's docker.io); without an image hub it
## makes a bookworm base with debootstrap. See deploy/docker/check.sh.
check-docker: mujoco
	deploy/docker/check.sh

## check-wgpu: build burn's wgpu backend and run the GPU smoke test. Without a GPU,
## Mesa's lavapipe (Debian's mesa-vulkan-drivers) provides a Vulkan device on the CPU.
check-wgpu: mujoco
	@ldconfig -p | grep -q libvulkan.so.1 || { sudo=""; [ "$$(id -u)" = 0 ] || sudo=sudo; \
	  $$sudo apt-get update -qq && $$sudo apt-get install -y -qq libvulkan1 mesa-vulkan-drivers; }
	$(CARGO) test --release --features wgpu --test wgpu_smoke

mujoco: system-deps $(MUJOCO_LIB) $(MJCF_FILES)

$(MUJOCO_LIB):
	@rm -rf $(MUJOCO_DIR)/download/mujoco && mkdir -p $(MUJOCO_DIR)/download $(MUJOCO_DIR)/lib
	$(PIP_DOWNLOAD) -d $(MUJOCO_DIR)/download mujoco==$(MUJOCO_VERSION)
	$(PYTHON) -m zipfile -e $(MUJOCO_DIR)/download/mujoco-$(MUJOCO_VERSION)-*.whl $(MUJOCO_DIR)/download/mujoco
	cp $(MUJOCO_DIR)/download/mujoco/mujoco/libmujoco.so.$(MUJOCO_VERSION) $(MUJOCO_DIR)/lib/
	ln -sf libmujoco.so.$(MUJOCO_VERSION) $@
	@rm -rf $(MUJOCO_DIR)/download/mujoco

$(MJCF_FILES) &:
	@rm -rf $(MUJOCO_DIR)/download/gymnasium && mkdir -p $(MUJOCO_DIR)/download $(MJCF_DIR)
	$(PIP_DOWNLOAD) -d $(MUJOCO_DIR)/download gymnasium==$(GYMNASIUM_VERSION)
	$(PYTHON) -m zipfile -e $(MUJOCO_DIR)/download/gymnasium-$(GYMNASIUM_VERSION)-py3-none-any.whl $(MUJOCO_DIR)/download/gymnasium
	cp $(addprefix $(MUJOCO_DIR)/download/gymnasium/gymnasium/envs/mujoco/assets/,$(notdir $(MJCF_FILES))) $(MJCF_DIR)/
	@rm -rf $(MUJOCO_DIR)/download/gymnasium

## system-deps: Debian packages the build needs, installed only when missing.
system-deps:
	@missing=""; \
	$(PYTHON) -c 'import ensurepip' 2>/dev/null || missing="$$missing python3-venv"; \
	$(PYTHON) -m pip --version >/dev/null 2>&1 || missing="$$missing python3-pip"; \
	pkg-config --exists hdf5 2>/dev/null || missing="$$missing libhdf5-dev pkg-config"; \
	if [ -n "$$missing" ]; then \
	  echo "installing Debian packages:$$missing"; \
	  sudo=""; [ "$$(id -u)" = 0 ] || sudo=sudo; \
	  $$sudo apt-get update -qq && $$sudo apt-get install -y -qq $$missing; \
	fi

## slurm: Debian's Slurm and munge, for the experiment runner's test against a
## real single-node cluster (deploy/slurm/local-cluster.sh starts and stops it).
slurm:
	@command -v slurmctld >/dev/null && command -v munged >/dev/null || { \
	  echo "installing Debian packages: slurm-wlm munge"; \
	  sudo=""; [ "$$(id -u)" = 0 ] || sudo=sudo; \
	  $$sudo apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$sudo apt-get install -y -qq slurm-wlm munge; }

## venv: the Python side of the tests (Gymnasium parity, h5py/safetensors read-backs).
venv: system-deps $(VENV_STAMP)

# The Python package (clients/python) is installed into the same venv, whose pins
# supply its dependencies; any change to it reinstalls it.
PYTHON_PACKAGE := clients/python/pyproject.toml $(shell find clients/python/nuno -name '*.py' 2>/dev/null)

$(VENV_STAMP): tests/python/requirements.txt $(PYTHON_PACKAGE)
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install --quiet --disable-pip-version-check -r tests/python/requirements.txt
	$(VENV)/bin/pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation ./clients/python
	touch $@

clean-runtime:
	rm -rf $(MUJOCO_DIR) $(VENV)
