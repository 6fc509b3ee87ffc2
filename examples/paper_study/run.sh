#!/usr/bin/env bash
# Regenerate docs/paper-study.md and docs/paper-study/*.png: the Monte-Carlo test of the
# paper's claim (500 trials, seed 1, a few minutes on 2 cores). Extra arguments are passed on,
# e.g. `examples/paper_study/run.sh --trials 50 -o /tmp/study.md` for a quick look.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
PY="${PYTHON:-$ROOT/.venv/bin/python}"
export PYTHONPATH="$ROOT/plugins/python${PYTHONPATH:+:$PYTHONPATH}"
export STIFF_BUILD_DIR="${STIFF_BUILD_DIR:-$ROOT/build}"
exec "$PY" -m stiff.cli study paper --trials 500 --seed 1 -o docs/paper-study.md \
  --plots docs/paper-study "$@"
