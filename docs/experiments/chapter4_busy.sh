#!/usr/bin/env bash
# Issue 34's last goal: chapter 4 end to end (docs/experiments/chapter4.sh) at `nice -n 10` beside a process that
# spins on a core the whole time. Run it from a fresh clone with the package installed (`pip install -e .`):
#   bash docs/experiments/chapter4_busy.sh
# It prints how long chapter4.sh took and its exit code; each run's status is in runs/chapter4/*/summary.json.
set -uo pipefail
cd "$(dirname "$0")/../.."
python3 -c "while True: pass" &
busy=$!
trap 'kill $busy 2>/dev/null' EXIT
echo "busy process $busy; chapter4.sh at nice 10 from $(date -u +%FT%TZ), load: $(cut -d' ' -f1-3 /proc/loadavg)"
start=$(date +%s)
nice -n 10 bash docs/experiments/chapter4.sh
rc=$?
echo "chapter4.sh exit code $rc at $(date -u +%FT%TZ) after $(($(date +%s) - start)) s"
exit $rc
