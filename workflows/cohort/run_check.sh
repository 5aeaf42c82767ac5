#!/usr/bin/env bash
# Runs the cohort workflow on its two phantoms and two plans into WORK_DIR with the given caps
# program, checks that results.tsv has one row per patient x plan and that a rerun has nothing to do.
#   workflows/cohort/run_check.sh build/tools/caps /tmp/cohort
set -euo pipefail
caps="$1"
work="$2"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
rm -rf "$work"
args=(-s "$here/Snakefile" --configfile "$here/config.yaml" --config "caps=$caps"
      --directory "$work" --cores 2)
snakemake "${args[@]}" --keep-going -q
rows=$(($(wc -l < "$work/results.tsv") - 1))
[ "$rows" -eq 4 ] || { echo "results.tsv has $rows rows, expected 4"; exit 1; }
snakemake "${args[@]}" -n | grep -q "Nothing to be done" || { echo "a rerun would do work"; exit 1; }
echo "cohort: $rows rows; a rerun has nothing to do"
