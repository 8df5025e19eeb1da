#!/usr/bin/env bash
# Start a link hub and one companion per running PX4 SITL instance (default: instances 0 and 1).
#   scripts/start_companions.sh [N] [--loss P]
# Stops everything on Ctrl-C.  Needs `make demo` or `make test` to have built .venv first.
set -euo pipefail
cd "$(dirname "$0")/.."
count="${1:-2}"
shift || true
PY=.venv/bin/python
[ -x "$PY" ] || { echo "no .venv: run 'make test' or 'make demo' first" >&2; exit 2; }
pids=()
trap 'kill "${pids[@]}" 2>/dev/null || true; wait' INT TERM EXIT
"$PY" -m companion link-hub --port 14600 "$@" &
pids+=($!)
sleep 1
for ((i = 0; i < count; i++)); do
    config="sitl_configs/companion$i.toml"
    if [ -f "$config" ]; then
        "$PY" -m companion run --config "$config" &
    else
        "$PY" -m companion run --node $((i + 1)) --autopilot "udpin://0.0.0.0:$((14540 + i))" \
            --hub 127.0.0.1:14600 &
    fi
    pids+=($!)
done
wait
