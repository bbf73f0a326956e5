#!/usr/bin/env bash
# Warm wall times of `opa-mc validate --quiet` from two source trees, alternated, each in a
# fresh output folder (issue 29): on a machine whose load changes from minute to minute,
# alternating the two puts each pair under about the same load.
#
#   git worktree add /tmp/base COMMIT          # the tree to compare with (its own numba cache)
#   bash benchmarks/alternate.sh /tmp/base . 3 [validate's flags ...]
#
# Prints per run: the tree, the pair, the load average before it and the wall seconds
# from the process's start to its end. Run each tree once before (numba's cache). The
# interpreter: $PYTHON, else `python` (the environment with opa-mc's dependencies).
set -euo pipefail
base=$(cd "$1" && pwd); new=$(cd "$2" && pwd); pairs=${3:-3}
shift 3 || shift $#
out=$(mktemp -d)
for i in $(seq "$pairs"); do
  for tree in "$base" "$new"; do
    rm -rf "$out/run"
    load=$(cut -d' ' -f1 /proc/loadavg)
    start=$(date +%s.%N)
    if ! (cd "$tree" && PYTHONPATH="$tree" MPLBACKEND=Agg "${PYTHON:-python}" -c \
      "import sys; from opa.cli._main import main; sys.exit(main(sys.argv[1:]))" \
      validate --quiet --outdir "$out/run" "$@" > "$out/log" 2>&1); then
      echo "$tree: validate failed:" >&2; tail -5 "$out/log" >&2; exit 1
    fi
    end=$(date +%s.%N)
    printf '%s pair %d load %s wall %.1f s\n' "$tree" "$i" "$load" "$(echo "$end - $start" | bc)"
  done
done
rm -rf "$out"
