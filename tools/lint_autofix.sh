#!/usr/bin/env bash
# Bring the tree to the rule families ruff gained with the stricter gates (I: import order, PT: pytest
# style, SIM: simplifications, RUF100: no noqa that silences nothing) in one mechanical pass, then show
# what is left. Run once after the branches that predate those rules are merged; afterwards `make lint`
# keeps the tree there and this script has nothing left to do.
#
# The fixes ruff calls unsafe are allowed for four rules only, each checked to change no behaviour here:
#   PT006  @pytest.mark.parametrize("a, b", ...) -> ("a", "b"): pytest reads both alike
#   PT022  a fixture that yields with nothing after it returns instead
#   SIM105 try/except X: pass -> with contextlib.suppress(X)
#   SIM401 x[k] if k in x else d -> x.get(k, d) on a Mapping
set -euo pipefail
cd "$(dirname "$0")/.."
RUFF=${RUFF:-.venv/bin/ruff}
# the unsafe four first: SIM105 adds an import, which the import-order pass then puts in its place
"$RUFF" check . --fix --unsafe-fixes --fixable PT006,PT022,SIM105,SIM401 --exit-zero --silent
"$RUFF" check . --fix --fixable I,PT,SIM,RUF100 --exit-zero --silent
# what no rule can fix: each needs a hand (or, for C901, a function split in two)
exec "$RUFF" check . --output-format concise
