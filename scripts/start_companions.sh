#!/usr/bin/env bash
# Start a link hub and one companion per running PX4 SITL instance (default: instances 0 and 1).
#   scripts/start_companions.sh [N] [--loss P]
# Every companion needs an identity: the first time, this makes a demo operator key
# (out/keys/fleet.key) and a key and certificate per drone with `python -m companion keys`
# (kept: a drone's key is its identity).  Stops everything on Ctrl-C.  Needs `make demo` or
# `make test` to have built .venv first.
set -euo pipefail
cd "$(dirname "$0")/.."
count="${1:-2}"
shift || true
PY=.venv/bin/python
[ -x "$PY" ] || { echo "no .venv: run 'make test' or 'make demo' first" >&2; exit 2; }
keys=out/keys
mkdir -p "$keys"
[ -f "$keys/fleet.key" ] || "$PY" -m companion keys init "$keys/fleet.key"
for ((i = 0; i < count; i++)); do
    node=$((i + 1))
    [ -f "$keys/drone$node.key" ] || "$PY" -m companion keys init "$keys/drone$node.key"
    [ -f "$keys/drone$node.cert" ] || "$PY" -m companion keys certify \
        --operator-key "$keys/fleet.key" --drone "$keys/drone$node.pub" --node "$node" \
        --out "$keys/drone$node.cert"
    config="sitl_configs/companion$i.toml"
    if [ ! -f "$config" ]; then  # instances beyond the shipped configs: one made here
        config="out/companion$i.toml"
        cat > "$config" <<TOML
node = $node
autopilot = "udpin://0.0.0.0:$((14540 + i))"
[link]
hub = "127.0.0.1:14600"
[identity]
key = "keys/drone$node.key"
certificate = "keys/drone$node.cert"
state_dir = "state/drone$node"
[[trust.operator]]
name = "fleet"
key = "keys/fleet.pub"
TOML
    fi
done
pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; wait' INT TERM EXIT
"$PY" -m companion link-hub --port 14600 "$@" &
pids+=($!)
sleep 1
for ((i = 0; i < count; i++)); do
    config="sitl_configs/companion$i.toml"
    [ -f "$config" ] || config="out/companion$i.toml"
    "$PY" -m companion run --config "$config" &
    pids+=($!)
done
wait
