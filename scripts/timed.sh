#!/bin/sh
# Runs one step of `make bench` and prints its wall-clock time (and exit status) after it.
start=$(date +%s)
"$@"
rc=$?
echo "[make bench] $(( $(date +%s) - start )) s, exit $rc: $*"
exit $rc
