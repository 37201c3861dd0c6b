# kinepost service image: multi-stage build, small runtime, non-root, health-checked.
# Machines and dialects are baked in at /opt/kinepost/{machines,dialects}; mount another library
# over either to change them.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY .cargo .cargo
COPY src src
COPY benches benches
COPY machines machines
COPY dialects dialects
RUN cargo build --release --locked --bin kinepost

FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home-dir /var/lib/kinepost --create-home kinepost \
    && mkdir -p /var/lib/kinepost/data /var/lib/kinepost/spool \
    && chown kinepost /var/lib/kinepost/data /var/lib/kinepost/spool
COPY --from=build /src/target/release/kinepost /usr/local/bin/kinepost
COPY machines /opt/kinepost/machines
COPY dialects /opt/kinepost/dialects
ENV KINEPOST_MACHINES=/opt/kinepost/machines \
    KINEPOST_DIALECTS=/opt/kinepost/dialects \
    KINEPOST_BIND=0.0.0.0:8080 \
    KINEPOST_DATA_DIR=/var/lib/kinepost/data \
    KINEPOST_LOG_FORMAT=json
USER kinepost
WORKDIR /var/lib/kinepost
VOLUME ["/var/lib/kinepost/data"]
EXPOSE 8080
# No curl in the slim image: bash's /dev/tcp asks /healthz on the port KINEPOST_BIND names (a
# wildcard address is asked on loopback).
HEALTHCHECK --interval=15s --timeout=3s --start-period=5s --retries=3 \
  CMD ["bash", "-c", "h=${KINEPOST_BIND%:*}; p=${KINEPOST_BIND##*:}; case $h in 0.0.0.0|'[::]'|'') h=127.0.0.1;; esac; h=${h#[}; h=${h%]}; exec 3<>/dev/tcp/$h/$p && printf 'GET /healthz HTTP/1.0\\r\\n\\r\\n' >&3 && grep -q '^ok' <&3"]
ENTRYPOINT ["kinepost"]
CMD ["serve"]
