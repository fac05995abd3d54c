# Sourced by the daemon benchmarks: starts "$build/server/isostreamd" on a free loopback port
# with the arguments given, logging to "$log", and sets `daemon` (its pid) and `address`; the
# daemon and "$log" go when the script exits.
start_daemon() {
  "$build/server/isostreamd" --listen 127.0.0.1:0 "$@" >"$log" 2>&1 &
  daemon=$!
  trap 'kill $daemon 2>/dev/null; wait $daemon 2>/dev/null; rm -rf "$log" ${scratch:-}' EXIT
  for _ in $(seq 100); do grep -q "listening on" "$log" && break; sleep 0.1; done
  address=$(grep -o "listening on [^ ]*" "$log" | head -1 | awk '{print $3}')
  [ -n "$address" ] || { cat "$log"; exit 1; }
}
