# The `seasonstereo` binary in a slim image, for Kubernetes jobs (docs/jobs/*.yaml) or any
# container runtime.
#
#   docker build -t seasonstereo:cpu .                              # CPU (default)
#   docker build --build-arg FEATURES=cuda \
#       --build-arg RUNTIME=nvidia/cuda:12.4.1-runtime-ubuntu22.04 -t seasonstereo:cuda .
#
# The CUDA variant also needs the CUDA toolkit in the build stage (burn's cuda backend compiles
# kernels at run time through NVRTC, which the runtime image provides); run it with `--gpus all`.
ARG RUNTIME=debian:bookworm-slim

# The toolchain of the workspace's rust-version (burn 0.22 needs 1.95), on the runtime's Debian
# release so that the binary finds the same glibc.
FROM rust:1.95-bookworm AS build
ARG FEATURES=""
WORKDIR /src
COPY . .
RUN cargo build --release --locked ${FEATURES:+--features "$FEATURES"} \
    && cp target/release/seasonstereo /usr/local/bin/seasonstereo

FROM ${RUNTIME}
RUN apt-get update && apt-get install -y --no-install-recommends ca-certificates \
    && rm -rf /var/lib/apt/lists/*
COPY --from=build /usr/local/bin/seasonstereo /usr/local/bin/seasonstereo
ENTRYPOINT ["seasonstereo"]
