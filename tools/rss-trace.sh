#!/bin/bash
# Peak and trace of a command's memory: runs COMMAND under /usr/bin/time -v and samples its
# resident set every 0.5 s, so that a peak can be placed in a build's stages.
#
#   tools/rss-trace.sh OUT COMMAND [ARGS...]
#
# Writes OUT (seconds since start, RSS in kB, one line per sample), OUT.out (the command's
# output) and OUT.err (its errors, then /usr/bin/time's report with the peak). docs/results.md,
# "The large city's full grid", was measured with
#   tools/rss-trace.sh /tmp/large/rss target/release/hdov build /tmp/large/city.json --out /tmp/large/city2.hdov --force
set -u
if [ $# -lt 2 ]; then
    echo "usage: $0 OUT COMMAND [ARGS...]" >&2
    exit 2
fi
out=$1
shift
: > "$out"
start=$(date +%s.%N)
/usr/bin/time -v "$@" > "$out.out" 2> "$out.err" &
timer=$!
sleep 0.2
while kill -0 "$timer" 2> /dev/null; do
    child=$(pgrep -P "$timer" | head -1)
    if [ -n "$child" ]; then
        rss=$(awk '/VmRSS/ {print $2}' "/proc/$child/status" 2> /dev/null)
        [ -n "$rss" ] && echo "$(echo "$(date +%s.%N) - $start" | bc) $rss" >> "$out"
    fi
    sleep 0.5
done
wait "$timer"
