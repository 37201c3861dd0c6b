# Placeholder until the HTTP service lands (issue 4): builds the CLI and ships the machine library.
# The service image (multi-stage, non-root, HEALTHCHECK, mountable machines) is issue 4's.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 kinepost
COPY --from=build /src/target/release/kinepost /usr/local/bin/kinepost
COPY machines /opt/kinepost/machines
ENV KINEPOST_MACHINES=/opt/kinepost/machines
USER kinepost
ENTRYPOINT ["kinepost"]
CMD ["machines"]
