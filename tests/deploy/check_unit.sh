#!/usr/bin/env bash
# Checks deploy/isostreamd.service against the daemon it starts:
#  1. the unit is valid (systemd-analyze verify, ExecStart pointed at the built daemon);
#  2. its sandbox leaves an exposure of at most 2.0 (systemd-analyze security, 0 best, 10 worst);
#  3. isostreamd, traced while it starts from a config file, prepares a generated and a raw file
#     volume (hierarchy cache written, then read by a second start), serves frames (Draco and
#     raw, eps and budget, progressive), refuses an unknown volume and stops on SIGTERM, makes
#     only system calls the unit's SystemCallFilter allows, opens only socket families
#     RestrictAddressFamilies allows, and maps no memory writable and executable
#     (MemoryDenyWriteExecute would kill it).
# systemd can't run here (no init), so (3) is how the filter is known to fit the daemon.
# Usage: check_unit.sh UNIT ISOSTREAMD ISOSTREAM_CLI
set -euo pipefail
unit=$(realpath "$1") daemon=$(realpath "$2") cli=$(realpath "$3")
for tool in systemd-analyze strace; do
  if ! command -v "$tool" >/dev/null; then
    echo "check_unit: $tool is missing (scripts/install-deps.sh)"
    exit 1
  fi
done
if ! strace -f -qq -o /dev/null true 2>/dev/null; then
  echo "check_unit: SKIPPED: this machine does not permit ptrace (strace)," \
    "so the daemon's system calls cannot be checked"
  exit 77
fi
work=$(mktemp -d)
tracer=""  # strace of the daemon running now, if any: a failed check must not leave it behind
cleanup() {
  if [ -n "$tracer" ]; then  # the daemon first: strace reaps it, then ends
    pkill -KILL -P "$tracer" 2>/dev/null || true
    wait "$tracer" 2>/dev/null || true
  fi
  rm -rf "$work"
}
trap cleanup EXIT

# 1-2. The unit as installed, but starting the built binary (verify wants it to exist).
# Quoted: systemd splits an unquoted path at its spaces.
sed "s|^ExecStart=/usr/local/bin/isostreamd|ExecStart=\"$daemon\"|" "$unit" >"$work/isostreamd.service"
systemd-analyze verify "$work/isostreamd.service"
if ! systemd-analyze security --offline=true --threshold=20 "$work/isostreamd.service" \
  >"$work/security"; then
  grep -E "✗|Overall" "$work/security"
  echo "check_unit: exposure above 2.0"
  exit 1
fi
tail -1 "$work/security"

# 3. The filter the unit sets: allowed groups minus denied ones, expanded to system calls.
filter() { sed -n "s/^SystemCallFilter=\(~\?\)\(.*\)/\1 \2/p" "$unit"; }
expand() {
  systemd-analyze syscall-filter "$1" | tail -n +2 | sed 's/#.*//' | awk 'NF {print $1}' |
    while read -r word; do
      case "$word" in @*) expand "$word" ;; *) echo "$word" ;; esac
    done
}
: >"$work/allow"
: >"$work/deny"
while read -r sign groups; do
  if [ -z "$groups" ]; then groups=$sign sign=""; fi
  for g in $groups; do
    if [ "$sign" = "~" ]; then expand "$g" >>"$work/deny"; else expand "$g" >>"$work/allow"; fi
  done
done < <(filter)
[ -s "$work/allow" ] || { echo "check_unit: no SystemCallFilter allow list in $unit"; exit 1; }
sort -u -o "$work/allow" "$work/allow"
sort -u -o "$work/deny" "$work/deny"

# A 33^3 uint8 raw volume: distance from the centre.
LC_ALL=C awk 'BEGIN { n = 33
  for (z = 0; z < n; z++) for (y = 0; y < n; y++) for (x = 0; x < n; x++) {
    v = int(255 * sqrt((x - 16) ^ 2 + (y - 16) ^ 2 + (z - 16) ^ 2) / 28)
    printf "%c", (v > 255 ? 255 : v)
  } }' \
  >"$work/vol.raw"
cat >"$work/config.json" <<JSON
{"listen": "127.0.0.1:0", "cache_dir": "$work/cache", "preload": true, "shutdown_grace_ms": 2000,
 "volumes": {"ball": "buckyball:65", "raw": "raw:$work/vol.raw:33x33x33:uint8"}}
JSON

serve() {  # one daemon lifetime under strace, with a few requests
  local log=$work/daemon$1.log
  strace -f -qq -o "$work/trace$1" "$daemon" --config "$work/config.json" >"$log" 2>&1 &
  tracer=$!
  local address=""
  for _ in $(seq 300); do
    address=$(grep -o "listening on [^ ]*" "$log" | head -1 | awk '{print $3}') || true
    [ -n "$address" ] && break
    sleep 0.1
  done
  [ -n "$address" ] || { cat "$log"; echo "check_unit: the traced daemon did not start"; exit 1; }
  fetch() {
    local said
    said=$(timeout 60 "$cli" fetch --server "$address" -o "$work/frame.ply" "$@" 2>&1) ||
      { echo "$said"; echo "check_unit: fetch $* failed"; exit 1; }
  }
  fetch --volume ball --eye 2,2,2 --iso 0.1 --eps 0.01
  fetch --volume ball --eye 2,2,2 --iso 0.1,0.2 --budget 20000 --progressive
  fetch --volume raw --iso 100 --eps 0 --view-dir 1,1,1 --codec raw
  if timeout 60 "$cli" fetch --server "$address" --volume nope --iso 0.1 --eps 0 --eye 2,2,2 \
    -o "$work/frame.ply" >/dev/null 2>&1; then
    echo "check_unit: an unknown volume was served"
    exit 1
  fi
  local pid
  pid=$(pgrep -P "$tracer") || { cat "$log"; echo "check_unit: the traced daemon is gone"; exit 1; }
  kill -TERM "$pid"
  local code=0
  wait "$tracer" || code=$?
  tracer=""
  # strace exits with the daemon's status; "stopped" is the daemon's last line.
  if [ "$code" != 0 ] || ! grep -q "\] stopped$" "$log"; then
    cat "$log"
    echo "check_unit: the daemon did not stop cleanly (exit $code)"
    exit 1
  fi
}
serve 1  # builds and caches both hierarchies
serve 2  # reads them back
[ -n "$(ls -A "$work/cache")" ] || { echo "check_unit: nothing was cached"; exit 1; }

cat "$work/trace1" "$work/trace2" >"$work/trace"
awk '{ line = $0; sub(/^[0-9]+ +/, "", line); sub(/^<\.\.\. /, "", line)
       if (match(line, /^[a-z0-9_]+[( ]/)) print substr(line, 1, RLENGTH - 1) }' "$work/trace" |
  sort -u >"$work/used"
failed=0
outside=$(comm -23 "$work/used" "$work/allow")
denied=$(comm -12 "$work/used" "$work/deny")
if [ -n "$outside$denied" ]; then
  echo "check_unit: system calls the unit's SystemCallFilter refuses:" $outside $denied
  failed=1
fi
families=$(grep -oE "socket\(AF_[A-Z0-9]+" "$work/trace" | sed 's/socket(//' | sort -u)
allowed_families=$(sed -n 's/^RestrictAddressFamilies=//p' "$unit")
for f in $families; do
  case " $allowed_families " in
    *" $f "*) ;;
    *) echo "check_unit: socket family $f is not allowed"; failed=1 ;;
  esac
done
if grep -E "^[0-9]+ +(mmap|mprotect|pkey_mprotect)\(.*PROT_WRITE\|PROT_EXEC" "$work/trace"; then
  echo "check_unit: writable executable memory (MemoryDenyWriteExecute)"
  failed=1
fi
if grep -E "^[0-9]+ +(mprotect|pkey_mprotect)\(.*PROT_EXEC" "$work/trace"; then
  echo "check_unit: memory made executable after mapping (MemoryDenyWriteExecute)"
  failed=1
fi
[ "$failed" = 0 ] || exit 1
echo "check_unit: $(wc -l <"$work/used") distinct system calls, all allowed;" \
  "socket families:" $families
